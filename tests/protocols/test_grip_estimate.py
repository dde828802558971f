"""A grip trial with an estimator artifact logs the live estimate beside the skin frames."""

from __future__ import annotations

import numpy as np
import pytest

from layerskin_exp.estimation import CnnGruForceModel, Estimator, OnlineEstimator, Preprocessor, SlipDetector
from layerskin_exp.estimation.cnn import CnnGru
from layerskin_exp.log import load_session
from protocols.config import GripDepthConfig
from protocols.grip import run_grip_trial
from tests.protocols.fake_rig import gripper_rig
from tests.protocols.test_logic import META, _connected


def _artifact(path):
    pre = Preprocessor()
    pre.layer_scale_ = np.array([5000.0, 5000.0], np.float32)
    model = CnnGruForceModel("T-s5")
    model.model_ = CnnGru(3).eval()
    model.norm_ = {"x_mean": np.zeros(3, np.float32), "x_std": np.ones(3, np.float32),
                   "y_mean": np.array([0.0, 0.0, 2.0], np.float32), "y_std": np.ones(3, np.float32)}
    det = SlipDetector.from_dict({**SlipDetector(84.8).get_params(), "median": 0.0, "mad": 1.0, "threshold": 3.0,
                                  "offset_s": 0.0})
    return Estimator(pre, model, det, "interlayer").save(path)


def test_grip_session_carries_the_estimates_of_its_own_frames(tmp_path):
    art = _artifact(tmp_path / "T-s5.pt")
    cfg = GripDepthConfig(hardware={}, skin={}, data_root=str(tmp_path / "data"), grip_depth=6.0, progress=False,
                          estimator=str(art))
    cfg.trajectory.translation.waypoints_mm = [0.0, 1.0, 0.0]
    result = run_grip_trial(cfg, _connected(gripper_rig(rod_contact_mm=20.0)), META)
    s = load_session(result.path, warn=False)
    skin, est, slip = s.streams["skin"], s.streams["estimate_force"], s.streams["estimate_slip"]
    assert est["force_n"].shape[1] == 3 and len(est["seq"]) == len(slip["seq"])
    # About one estimate per five frames (frames 0-2 come together with the baseline, the last
    # one or two need frames after the trial).
    assert len(skin["seq"]) // 5 - 4 <= len(est["seq"]) <= len(skin["seq"]) // 5
    # The logged estimates are the online estimator's on the logged frames.
    online = OnlineEstimator.from_artifact(art)
    ref = {}
    for a, b, t in zip(skin["superficial"], skin["deep"], skin["device_t_ns"], strict=True):
        e = online.update(a, b, int(t))
        if e is not None and e.new:
            ref[e.frame] = e
    np.testing.assert_allclose(est["force_n"], np.stack([ref[k].force_n for k in est["seq"]]), atol=1e-5)
    np.testing.assert_allclose(slip["score"], [ref[k].slip_score for k in slip["seq"]], atol=1e-6)
    assert slip["slip"].dtype == bool


def test_a_missing_artifact_is_refused_before_the_trial():
    with pytest.raises(ValueError, match="estimator"):
        GripDepthConfig(hardware={}, skin={}, estimator="/no/such/T-s5.pt")
