"""The state of one report run, the type every section (`analysis.sections`) takes: below both
the sections and `analysis.report`, which runs them, so neither imports the other in a circle."""

from __future__ import annotations

import json
import logging
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from omegaconf import OmegaConf

from analysis import study
from analysis.config import ReportConfig
from analysis.markdown import json_safe, write_markdown
from analysis.sessions import Campaign, load_campaign, shown
from layerskin_exp.features import two_layer_features

if TYPE_CHECKING:
    from layerskin_exp.estimation.cnn import CnnGruForceModel

log = logging.getLogger("analysis.report")


class ReportRun:
    """What one report run holds and the sections share: the loaded campaign, the results the
    sections fill, what earlier sections leave for later ones (ts5, calib_feats), the figures in
    self.out. The run's order of sections is `analysis.report.Analysis`'s, above both."""

    def __init__(self, cfg: ReportConfig, preset: str | None = None) -> None:
        """preset: the name of the analysis preset the config came from (Hydra's choice), for the record."""
        self.cfg, self.a, self.skin = cfg, cfg.analysis, cfg.skin
        self.preset = preset
        self.out = Path(cfg.out)
        self.results: dict = {"provenance": {}, "data": {}, "force": {}, "heights": {}, "characterization": {}, "tracking": {}, "slip": {},
                               "slip_causal": {},
                               "study": study.ALL, "skipped": {}, "inputs": {}, "timing_s": {}}
        self.figures: list[str] = []
        self.ts5: CnnGruForceModel | None = None
        self.camp: Campaign | None = None
        self.calib_feats: dict | None = None
        self._grip_force: dict[int, np.ndarray] = {}  # grip trial index -> T-s5 force (K, 3) N
        self._grip_feats: list[dict] | None = None

    def skip(self, section: str, reason: str) -> None:
        self.results["skipped"][section] = reason
        log.info("skipped %s: %s", section, reason)

    # -- stages ---------------------------------------------------------------------------
    def load(self) -> None:
        camp = load_campaign(self.cfg.sessions, self.a.preprocess, self.a.progress)
        self.camp = camp
        n_press = sum(t.labels.get("kind") == "press" for t in camp.calibration)
        self.results["inputs"] = {"sessions_dir": shown(self.cfg.sessions), "files": camp.n_files,
                                  "calibration_trials": len(camp.calibration), "press_trials": n_press,
                                  "slide_trials": len(camp.calibration) - n_press, "grip_trials": len(camp.grip),
                                  "skipped": dict(camp.skipped),
                                  "skipped_files": [{"file": f.name, "reason": f.reason, "detail": f.detail}
                                                    for f in camp.skipped_files]}
        self.results["data"] = {"sessions_used": len(camp.calibration) + len(camp.grip),
                                "sessions_skipped": len(camp.skipped_files),
                                "calibration_trials": len(camp.calibration), "grip_trials": len(camp.grip),
                                "calibration_frames": int(sum(len(t.t_s) for t in camp.calibration)),
                                "grip_frames": int(sum(len(t.t_s) for t in camp.grip))}
        log.info("sessions: %d used, %d skipped (%s)", self.results["data"]["sessions_used"],
                 len(camp.skipped_files), dict(camp.skipped) or "none")
        # Per-layer scale from the calibration campaign (else the grip sessions), applied to all.
        from layerskin_exp.estimation.preprocess import Preprocessor  # scikit-learn: when a report runs

        self.pre = Preprocessor.from_config(self.a.preprocess)
        src = [t.maps for t in camp.calibration] or [t.maps for t in camp.grip]
        if not src:
            self.pre.layer_scale_ = self.scale = np.ones(2, np.float32)
            return
        self.scale = self.pre.fit_unscaled(src).layer_scale_
        for t in [*camp.calibration, *camp.grip]:
            self.pre.scale(t.maps)
        self.results["inputs"]["layer_scale_counts"] = self.scale

    # -- shared by sections ---------------------------------------------------------------
    def grip_force(self, i: int) -> np.ndarray:
        """T-s5 force (K, 3) N of grip trial i, predicted once and shared by the preload and slip cues."""
        if i not in self._grip_force:
            self._grip_force[i] = self.ts5.predict(self.camp.grip[i].maps)
        return self._grip_force[i]

    def grip_features(self) -> list[dict]:
        """two_layer_features of every grip trial, computed once for tracking and slip."""
        if self._grip_feats is None:
            self._grip_feats = [two_layer_features(t.maps, self.skin, self.a.preprocess.eps) for t in self.camp.grip]
        return self._grip_feats

    def write(self) -> None:
        self.results["figures"] = self.figures
        (self.out / "config.yaml").write_text(OmegaConf.to_yaml(OmegaConf.structured(self.cfg)))
        (self.out / "results.json").write_text(json.dumps(json_safe(self.results), indent=1))
        write_markdown(self.out / "report.md", json_safe(self.results), self.figures)
        skipped = self.results["inputs"].get("skipped_files")
        if skipped:
            with open(self.out / "report.md", "a") as fh:
                fh.write("\n## Skipped files\n\n" + "".join(
                    f"- `{f['file']}`: {f['reason']}{': ' + f['detail'] if f['detail'] else ''}\n" for f in skipped))
