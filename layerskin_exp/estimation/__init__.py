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

from layerskin_exp.estimation.artifact import Estimator
from layerskin_exp.estimation.cnn import CnnGruForceModel
from layerskin_exp.estimation.detector import SlipDetector
from layerskin_exp.estimation.linear import LinearForceModel, linear_features
from layerskin_exp.estimation.online import Estimate, OnlineEstimator
from layerskin_exp.estimation.preprocess import DownsampleStream, Preprocessor

__all__ = ["CnnGruForceModel", "DownsampleStream", "Estimate", "Estimator", "LinearForceModel", "OnlineEstimator",
           "Preprocessor", "SlipDetector", "linear_features"]
