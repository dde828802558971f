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


class SkinView:
    """summary(frame) -> [(topic, schema, payload)] for one frame, or [] between display ticks.

    The first frame seen is the baseline (the skin unloaded at the start of a trial); CoP and
    totals are of the counts above it. min_total_counts: below it no CoP dot is drawn.
    """

    def __init__(self, skin: SkinConfig | None = None, period_ns: int = DISPLAY_PERIOD_NS,
                 min_total_counts: float = 200.0) -> None:
        self.skin = skin or SkinConfig()
        self.period_ns = int(period_ns)
        self.min_total_counts = float(min_total_counts)
        self._baseline: np.ndarray | None = None
        self._last_ns: int | None = None
        # taxel centre (mm) -> image pixel: column j's centre x_j lies at pixel x = j + 0.5
        c = np.asarray(self.skin.taxel_centres_mm(), float)
        self._px_per_mm = (len(c) - 1) / (c[-1] - c[0])
        self._origin_mm = c[0]

    def due(self, host_t_ns: int) -> bool:
        return self._last_ns is None or host_t_ns - self._last_ns >= self.period_ns

    def summary(self, frame: TwoLayerFrame) -> list[tuple[str, object, bytes]]:
        maps = np.stack([frame.superficial, frame.deep]).astype(np.float64)  # (2, 16, 16)
        if self._baseline is None:
            self._baseline = maps
        host = int(frame.host_t_ns)
        if not self.due(host):
            return []
        self._last_ns = host
        load = np.clip(maps - self._baseline, 0.0, None)
        totals = load.sum(axis=(1, 2))
        cops = centre_of_pressure(load, self.skin)  # (2, 2) mm
        body, out = {}, []
        for k, layer in enumerate(S.SKIN_TOPICS):
            loaded = totals[k] >= self.min_total_counts
            cop = cops[k] if loaded else np.full(2, np.nan)
            body[layer] = {"total_counts": float(totals[k]),
                           "cop_mm": [float(v) for v in cop] if loaded else []}
            px = (cop - self._origin_mm) * self._px_per_mm + 0.5
            # image rows run along +y like the map's rows
            # the annotation carries its image's timestamp: the writer supplies it (Unix time)
            out.append((S.cop_topic(layer), S.ImageAnnotations, partial(S.cop_payload, px)))
        out.append((S.SKIN_SUMMARY_TOPIC, "layerskin.SkinSummary", S.dumps(body)))
        return out
