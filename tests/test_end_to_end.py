"""The whole chain on the simulated rig: protocols write sessions, the report reads them.

A tiny campaign (2 positions, 2 presses + 2 slides each) and two grip depths x two translation
trials, through the same command lines a user types, then `analysis.report` on the folder.
"""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from analysis.config import AnalysisConfig, CnnConfig, SlipConfig
from analysis.report import run_report
from layerskin_exp.log import load_session

ROOT = Path(__file__).resolve().parents[1]


def _cli(*args: str) -> None:
    r = subprocess.run([sys.executable, "-m", *args], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]


@pytest.fixture(scope="module")
def sessions(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("e2e")
    data = root / "sessions"
    _cli("protocols.force_calibration", f"data_root={data}", "positions.count=2", "press.repeats=2",
         "slide.repeats=2", "progress=false", f"hydra.run.dir={root}/hydra_cal")
    _cli("protocols.grip_depth", "-m", "grip_depth=6,15", "trajectory=translation", "trial=range(2)",
         f"data_root={data}", "progress=false", f"hydra.sweep.dir={root}/hydra_grip")
    return data


def test_sessions_carry_their_streams_labels_and_outcomes(sessions):
    cal = sorted((sessions / "force_calibration").glob("*/*.mcap"))
    grip = sorted((sessions / "grip_depth").glob("*/*.mcap"))
    assert len(cal) == 8 and len(grip) == 4
    for p in cal:
        s = load_session(p, warn=False)
        assert s.complete and s.labels["protocol"] == "force_calibration"
        assert {"skin", "wrench", "stage", "events"} <= set(s.streams)
        assert "stop" in s.streams["events"]["kind"]
    for p in grip:
        s = load_session(p, warn=False)
        assert s.complete and s.labels["motion"] == "translation"
        assert {"skin", "tcp", "gripper", "markers", "events"} <= set(s.streams)
        # the deep layer follows the arm: its CoP travels while the arm goes +5 / -5 mm
        skin = s.streams["skin"]
        assert skin["deep"].max() > 500


def test_report_on_simulated_sessions(sessions, tmp_path):
    cfg = AnalysisConfig(cnn=CnnConfig(configurations=["T-s5"], max_epochs=1, patience=1, torch_threads=1),
                         slip=SlipConfig(n_thresholds=8, offset_step_s=0.05), progress=False)
    run_report(sessions, tmp_path, cfg)
    res = json.loads((tmp_path / "results.json").read_text())
    assert res["inputs"]["skipped"] == {}
    assert {"linear", "T-s5"} <= set(res["force"])
    assert np.isfinite(res["force"]["linear"]["Fz"]["r2"])
    for g in ("6", "15"):
        for layer in ("deep", "superficial"):
            t = res["tracking"]["translation"][layer][g]
            assert np.isfinite(t["a"]) and np.isfinite(t["mae"])
    assert set(res["slip"]["translation"]["interlayer"]) >= {"global", "grip", "oracle"}
    assert (tmp_path / "report.md").exists() and (tmp_path / "predictions.npz").exists()
