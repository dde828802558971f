"""What Foxglove draws on top of the raw streams: per-layer totals and centre of pressure at
display rate, as a plot-friendly JSON summary and as a dot on each layer's image.

Computed on at most one frame per `period_ns` of host time, so it costs acquisition nothing
measurable; the analysis never reads it (it recomputes features from the raw counts).
"""

from __future__ import annotations

from functools import partial

import numpy as np

from layerskin_exp.config import SkinConfig
from layerskin_exp.features import centre_of_pressure
from layerskin_exp.log.session import schema as S
from layerskin_exp.types import TwoLayerFrame

DISPLAY_PERIOD_NS = 33_000_000  # ~30 Hz
BASELINE_FRAMES = 16  # frames seen at the start of a trial (unloaded) that set baseline and noise
# Contact when a layer's total exceeds the noise total's mean by this many of its standard
# deviations: a one-sided normal tail of 3e-7, i.e. about one false dot a day at 30 Hz.
NOISE_Z = 5.0


def noise_total_threshold(residuals: np.ndarray, z: float = NOISE_Z) -> float:
    """The total of clip(counts - baseline, 0) that noise alone stays under, from unloaded frames.

    residuals: (K, 16, 16) counts minus their baseline, K unloaded frames of one layer. Each of
    the N taxels adds max(e, 0) of its noise e ~ N(0, s^2): mean s/sqrt(2 pi), variance
    s^2 (1/2 - 1/(2 pi)). Their sum over N taxels has mean N s/sqrt(2 pi) and standard deviation
    sqrt(N) s sqrt(1/2 - 1/(2 pi)); the threshold is that mean plus z of those deviations. s is
    the pooled residual spread, with the 1-count ADC step's rounding (1/12 count^2) as a floor.
    """
    r = np.asarray(residuals, float)
    n = r[0].size
    s = float(np.sqrt(r.var(ddof=1) + 1.0 / 12.0)) if r.size > 1 else 1.0
    mean = n * s / np.sqrt(2.0 * np.pi)
    sd = np.sqrt(n) * s * np.sqrt(0.5 - 0.5 / np.pi)
    return float(mean + z * sd)


class SkinView:
    """summary(frame) -> [(topic, schema, payload)] for one frame, or [] between display ticks;
    payload(t_ns) -> bytes, given the message's log time (SessionWriter.write_view).

    The first `baseline_frames` frames seen (the skin unloaded at the start of a trial) give
    each layer's baseline (their mean) and its noise; CoP and totals are of the counts above the
    baseline, and a CoP dot is drawn only on contact: when the layer's total exceeds what noise
    alone reaches (noise_total_threshold). Nothing is shown while the baseline is taken.
    """

    def __init__(self, skin: SkinConfig | None = None, period_ns: int = DISPLAY_PERIOD_NS,
                 baseline_frames: int = BASELINE_FRAMES) -> None:
        if baseline_frames < 2:
            raise ValueError(f"baseline_frames={baseline_frames}: need at least 2 frames to measure noise")
        self.skin = skin or SkinConfig()
        self.period_ns = int(period_ns)
        self.baseline_frames = int(baseline_frames)
        self._seen: list[np.ndarray] = []
        self._baseline: np.ndarray | None = None
        self.contact_total_counts: np.ndarray | None = None  # (2,) per-layer threshold, once known
        self._last_ns: int | None = None
        # taxel centre (mm) -> image pixel: column j's centre x_j lies at pixel x = j + 0.5
        c = np.asarray(self.skin.taxel_centres_mm(), float)
        self._px_per_mm = (len(c) - 1) / (c[-1] - c[0])
        self._origin_mm = c[0]

    def due(self, host_t_ns: int) -> bool:
        return self._last_ns is None or host_t_ns - self._last_ns >= self.period_ns

    def summary(self, frame: TwoLayerFrame) -> list[tuple[str, object, object]]:
        maps = np.stack([frame.superficial, frame.deep]).astype(np.float64)  # (2, 16, 16)
        if self._baseline is None:
            self._seen.append(maps)
            if len(self._seen) < self.baseline_frames:
                return []
            seen = np.stack(self._seen)  # (K, 2, 16, 16)
            self._baseline = seen.mean(axis=0)
            self.contact_total_counts = np.array(
                [noise_total_threshold(seen[:, k] - self._baseline[k]) for k in range(2)])
            self._seen = []
        host = int(frame.host_t_ns)
        if not self.due(host):
            return []
        self._last_ns = host
        load = np.clip(maps - self._baseline, 0.0, None)
        totals = load.sum(axis=(1, 2))
        cops = centre_of_pressure(load, self.skin)  # (2, 2) mm
        body, out = {}, []
        for k, layer in enumerate(S.SKIN_TOPICS):
            loaded = totals[k] > self.contact_total_counts[k]
            cop = cops[k] if loaded else np.full(2, np.nan)
            body[layer] = {"total_counts": float(totals[k]),
                           "cop_mm": [float(v) for v in cop] if loaded else []}
            px = (cop - self._origin_mm) * self._px_per_mm + 0.5
            # image rows run along +y like the map's rows; the annotation carries its image's
            # timestamp, which the writer supplies (Unix time)
            out.append((S.cop_topic(layer), S.ImageAnnotations, partial(S.cop_payload, px)))
        out.append((S.SKIN_SUMMARY_TOPIC, "layerskin.SkinSummary", partial(S.encode, "layerskin.SkinSummary", body)))
        return out
