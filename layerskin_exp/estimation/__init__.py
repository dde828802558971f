"""Force and slip estimation from the two-layer skin, for the report and for live use.

Offline (arrays in, arrays out, scikit-learn manners: hyperparameters in the constructor, fitted
state with trailing underscores, fit returns self, no global side effects):
    Preprocessor        raw counts -> scaled maps (smoothing, 5x downsampling, baseline, layer scale)
    LinearForceModel    the study's physics-inspired linear baseline (linear_features)
    CnnGruForceModel    the CNN-GRU (T/S/D x s1/s5)
    SlipDetector        causal slip detector (fit / score / score_samples / stream)
    slip                offline (acausal) cue scores, vision ground truth, matching, LOTO settings
    splits              trial-level split and windows
Deployment:
    Estimator           preprocessor + force model + slip detector, saved as one artifact
    OnlineEstimator     frame-by-frame estimates from an artifact (from_artifact)
    python -m layerskin_exp.estimation.export ARTIFACT --format onnx
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

# name -> the module that defines it; imported on first use, so that the schemas
# (layerskin_exp.estimation.config) load without torch and scikit-learn (a command's --help and
# config errors: benchmarks/cli_help)
_WHERE = {"Estimator": "artifact", "CnnGruForceModel": "cnn", "SlipDetector": "detector",
          "LinearForceModel": "linear", "linear_features": "linear", "Estimate": "online",
          "OnlineEstimator": "online", "DownsampleStream": "preprocess", "Preprocessor": "preprocess"}

__all__ = ["CnnGruForceModel", "DownsampleStream", "Estimate", "Estimator", "LinearForceModel", "OnlineEstimator",
           "Preprocessor", "SlipDetector", "linear_features"]

if TYPE_CHECKING:
    from layerskin_exp.estimation.artifact import Estimator
    from layerskin_exp.estimation.cnn import CnnGruForceModel
    from layerskin_exp.estimation.detector import SlipDetector
    from layerskin_exp.estimation.linear import LinearForceModel, linear_features
    from layerskin_exp.estimation.online import Estimate, OnlineEstimator
    from layerskin_exp.estimation.preprocess import DownsampleStream, Preprocessor


def __getattr__(name: str):
    if name not in _WHERE:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{_WHERE[name]}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted([*globals(), *__all__])
