"""One fitted estimator, one file: raw counts in, newtons (and a slip score) out.

The file (torch.save of plain values and tensors; `torch.load(weights_only=True)` reads it):

    format: "layerskin-estimator", format_version: 1
    preprocess: Preprocessor.to_dict() — ma_window, downsample, baseline_frames,
                scale_percentile, layer_scale (per layer, counts), and the rule in words
    force:      CnnGruForceModel.state() — configuration ("T-s5"), config, state_dict, norm
                (input channel mean/std, force mean/std), training history
    slip:       None, or {"cue": name, "detector": SlipDetector.to_dict()}

Nothing needed to go from counts to newtons lives outside it.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import torch

from layerskin_exp.estimation.cnn import CnnGruForceModel
from layerskin_exp.estimation.detector import SlipDetector
from layerskin_exp.estimation.preprocess import Preprocessor

FORMAT = "layerskin-estimator"
FORMAT_VERSION = 1
CAUSAL_CUES = ("interlayer", "superficial", "f_xyz", "f_z")  # computable frame by frame


def cue_values(cue: str, p_s, p_d, force_n=None) -> np.ndarray:
    """A per-frame slip cue from layer totals p_s, p_d (K,) (scaled maps) and the force (K, 3) N."""
    if cue == "interlayer":
        return np.abs(np.asarray(p_s) - np.asarray(p_d))
    if cue == "superficial":
        return np.asarray(p_s)
    if force_n is None:
        raise ValueError(f"cue {cue!r} needs the force estimate")
    if cue == "f_xyz":
        return np.linalg.norm(force_n, axis=-1)
    if cue == "f_z":
        return np.asarray(force_n)[..., 2]
    raise ValueError(f"cue {cue!r}: a live estimator supports {', '.join(CAUSAL_CUES)}")


class Estimator:
    """Preprocessor + force model (+ slip detector on one cue), fitted together.

    force_from_counts: one trial's raw counts (N, 2, 16, 16) -> (N // downsample, 3) force in N,
    the same numbers the report computes for that trial.
    """

    def __init__(self, preprocessor: Preprocessor, force_model: CnnGruForceModel,
                 slip_detector: SlipDetector | None = None, slip_cue: str = "interlayer") -> None:
        if slip_detector is not None and slip_cue not in CAUSAL_CUES:
            raise ValueError(f"slip_cue={slip_cue!r}: must be one of {', '.join(CAUSAL_CUES)}")
        self.preprocessor = preprocessor
        self.force_model = force_model
        self.slip_detector = slip_detector
        self.slip_cue = slip_cue

    def maps_from_counts(self, counts: np.ndarray) -> np.ndarray:
        return self.preprocessor.transform(np.asarray(counts))

    def force_from_counts(self, counts: np.ndarray) -> np.ndarray:
        return self.force_model.predict(self.maps_from_counts(counts))

    def slip_score_from_counts(self, counts: np.ndarray) -> np.ndarray:
        """One trial's causal slip score (N // downsample,), MAD units of the training envelope."""
        if self.slip_detector is None:
            raise RuntimeError("this estimator has no slip detector (fit one with the report's slip stage)")
        maps = self.maps_from_counts(counts)
        tot = maps.sum(axis=(-2, -1))
        force = self.force_model.predict(maps) if self.slip_cue in ("f_xyz", "f_z") else None
        return self.slip_detector.score_samples(cue_values(self.slip_cue, tot[:, 0], tot[:, 1], force))

    def to_dict(self) -> dict:
        slip = None
        if self.slip_detector is not None:
            slip = {"cue": self.slip_cue, "detector": self.slip_detector.to_dict()}
        return {"format": FORMAT, "format_version": FORMAT_VERSION, "preprocess": self.preprocessor.to_dict(),
                "force": self.force_model.state(), "slip": slip}

    def save(self, path) -> Path:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        buf = io.BytesIO()  # serialised here, written by Python: a full disk is an OSError naming the file
        torch.save(self.to_dict(), buf)
        try:
            path.write_bytes(buf.getvalue())
        except OSError as exc:
            path.unlink(missing_ok=True)
            raise OSError(exc.errno, exc.strerror or str(exc), str(path)) from None
        return path

    @classmethod
    def load(cls, path, device: str = "cpu") -> Estimator:
        try:
            d = torch.load(path, map_location="cpu", weights_only=True)
        except FileNotFoundError:
            raise FileNotFoundError(f"{path}: no such estimator artifact (the report writes out/models/T-s5.pt)") \
                from None
        if not isinstance(d, dict) or d.get("format") != FORMAT:
            raise ValueError(f"{path}: not a {FORMAT} artifact (a bare model checkpoint carries no preprocessing; "
                             "re-run the report to write one)")
        if d.get("format_version") != FORMAT_VERSION:
            raise ValueError(f"{path}: artifact format_version {d.get('format_version')}, this code reads "
                             f"{FORMAT_VERSION}")
        slip = d.get("slip")
        det = SlipDetector.from_dict(slip["detector"]) if slip else None
        return cls(Preprocessor.from_dict(d["preprocess"]), CnnGruForceModel.from_state(d["force"], device),
                   det, slip["cue"] if slip else "interlayer")
