"""The report end to end on a tiny synthetic campaign (SessionWriter files, closed-form contacts)."""

import json
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

from analysis.config import AnalysisConfig, CnnConfig, SlipConfig
from analysis.report import run_report

sys.path.insert(0, str(Path(__file__).parent))
from synthetic import write_campaign  # noqa: E402


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    return write_campaign(tmp_path_factory.mktemp("sessions"), n_positions=5, grip_depths=(6, 12), trials=2)


def _fast():
    return AnalysisConfig(cnn=CnnConfig(configurations=["T-s5"], max_epochs=1, patience=1, torch_threads=1),
                          slip=SlipConfig(n_thresholds=8, offset_step_s=0.05), progress=False)


def test_report_writes_results_predictions_markdown_and_figures(campaign, tmp_path):
    res = run_report(campaign, tmp_path, _fast())
    data = json.loads((tmp_path / "results.json").read_text())
    for key in ("force", "heights", "characterization", "tracking", "slip", "study"):
        assert key in data
    assert set(data["force"]) == {"linear", "T-s5"}
    assert set(data["force"]["linear"]["Fz"]) == {"r2", "mae"}
    # The linear model is exact up to noise on the closed-form moment balance.
    assert data["force"]["linear"]["Fz"]["r2"] > 0.9
    # Deep layer moves 0.8x the arm: the calibration slope is 1/0.8.
    assert data["tracking"]["translation"]["deep"]["12"]["a"] == pytest.approx(1.25, rel=0.05)
    assert set(data["slip"]["translation"]["interlayer"]) >= {"global", "grip", "oracle"}
    pred = np.load(tmp_path / "predictions.npz")
    ref = pred["reference"]
    err = np.abs(pred["pred_linear"] - ref).mean(axis=0)
    np.testing.assert_allclose(err[2], data["force"]["linear"]["Fz"]["mae"], rtol=1e-9)
    md = (tmp_path / "report.md").read_text()
    assert "0.914" in md and "Slip-event detection" in md
    for f in res["figures"]:
        assert (tmp_path / f).stat().st_size > 1000
    # The saved T-s5 model is an estimator artifact: raw counts to newtons with the slip detector.
    from layerskin_exp.estimation import Estimator

    est = Estimator.load(tmp_path / "models" / "T-s5.pt")
    np.testing.assert_allclose(est.preprocessor.layer_scale_, data["inputs"]["layer_scale_counts"], rtol=1e-6)
    assert est.slip_detector is not None and est.slip_cue == "interlayer"
    # The causal detector's F1 is reported beside the offline one for the causal cues, same protocol.
    causal = data["slip_causal"]["translation"]
    assert set(causal) == {"interlayer", "superficial", "f_xyz", "f_z"}
    assert causal["interlayer"]["n_truth_events"] == data["slip"]["translation"]["interlayer"]["n_truth_events"]
    assert 0.0 <= causal["interlayer"]["grip"] <= 1.0
    assert "causal vs offline" in md
    # The report says what produced it and how far its models got.
    assert md.startswith("# layerskin-exp report\n\n## Produced by")
    assert data["provenance"]["version"] and "git_dirty" in data["provenance"]
    assert data["force_training"]["T-s5"]["epochs"] == 1 and not data["force_training"]["T-s5"]["converged"]
    assert "not converged" in md and "study: Fx, Fy within about" in md
    # the CNN's gain over linear is in the markdown as in results.json (interval, or '–' if undefined)
    gain_fx = data["force_gain_over_linear"]["T-s5"]["Fx"][0]
    assert "| axis | T-s5 − linear |" in md and f"| Fx | {gain_fx:+.3f} [" in md
    split = data["data"]["split"]
    assert sum(p["frames"] for p in split.values()) == data["data"]["calibration_frames"]
    assert "max_epochs: 1" in (tmp_path / "config.yaml").read_text()


def test_missing_grip_sessions_are_skipped_with_a_reason(campaign, tmp_path):
    only_cal = tmp_path / "cal"
    shutil.copytree(campaign / "force_calibration", only_cal)
    (only_cal / "broken.mcap").write_bytes(b"not an mcap file")
    out = tmp_path / "out"
    res = run_report(only_cal, out, _fast())
    assert "grip_depth" in res["skipped"]["tracking"]
    assert "grip_depth" in res["skipped"]["slip"]
    assert res["inputs"]["skipped"] == {"unreadable file": 1}
    assert "Skipped sections" in (out / "report.md").read_text()


def test_empty_folder_gives_a_report_not_a_crash(tmp_path):
    (tmp_path / "none").mkdir()
    res = run_report(tmp_path / "none", tmp_path / "out", _fast())
    assert set(res["skipped"]) >= {"force", "characterization", "tracking", "slip"}


def test_sensitivity_bands_sit_beside_the_study_in_markdown_and_json(campaign, tmp_path):
    from synthetic import write_sensitivity_result

    sens = write_sensitivity_result(tmp_path / "sens.json")
    only_cal = tmp_path / "cal"
    shutil.copytree(campaign / "force_calibration", only_cal)
    cfg = _fast()
    cfg.figures = False
    run_report(only_cal, tmp_path / "out", cfg, sensitivity=sens)
    data = json.loads((tmp_path / "out" / "results.json").read_text())
    c = data["characterization"]
    rows = {r["outcome"]: r for r in c["sensitivity_bands"]["rows"]}
    # this campaign's value is the section's own measurement
    assert rows["cop_shift_at_2n_mm"]["ours"] == c["cop_shift"]["median_mm"]
    assert rows["position_cv"]["ours"] == c["uniformity"]["cv"]
    assert rows["slide_fz_at_shear_n"]["ours"] == c["slide_loads"]["fz_at_shear_n"] is not None
    md = (tmp_path / "out" / "report.md").read_text()
    part = md[md.index("### Simulator sensitivity bands"):]
    assert "not measurement noise" in part and "layerskin_exp/sim/brackets.yaml" in part
    assert ("| inter-layer shift at 2 N shear (mm) | 2.2 (Sec. IV-A" in part
            and f"| {rows['cop_shift_at_2n_mm']['ours']:.3g} (this section) | 1 .. 1.5 |" in part)
    # a study value outside the band is said in words, one inside too; no verdict
    assert "the study's 2.2 mm lies above the band (1 .. 1.5 mm)" in part
    assert "the study's 3.74 N lies below the band (4 .. 9 N)" in part
    assert "the study's 0.145 lies inside the band" in part
    assert "the study's ≈ 6 N lies above the band (4.1 .. 4.3 N)" in part
    assert "2 of 8 samples undefined" in part and "undefined in every sample" in part
    assert "PASS" not in part.upper().replace("PASS/FAIL", "")


def test_without_a_screening_result_the_report_says_how_to_make_one(campaign, tmp_path):
    only_cal = tmp_path / "cal"
    shutil.copytree(campaign / "force_calibration", only_cal)
    cfg = _fast()
    cfg.figures = False
    run_report(only_cal, tmp_path / "out", cfg)
    md = (tmp_path / "out" / "report.md").read_text()
    assert "Sensitivity bands: none given. `python -m protocols.sensitivity out=FILE`" in md
    assert "sensitivity=FILE" in md
    assert "sensitivity_bands" not in json.loads((tmp_path / "out" / "results.json").read_text())["characterization"]


def test_a_missing_screening_result_is_refused_before_anything_runs(campaign, tmp_path):
    import subprocess

    from analysis.config import ReportConfig
    from layerskin_exp.config import ConfigError

    nope = tmp_path / "nope.json"
    with pytest.raises(ConfigError, match=f"sensitivity={nope}: no such file"):
        run_report(campaign, tmp_path / "lib", _fast(), sensitivity=nope)
    assert not (tmp_path / "lib").exists()
    with pytest.raises(ConfigError, match="sensitivity="):
        ReportConfig(sensitivity=str(tmp_path))
    out = tmp_path / "cli"
    r = subprocess.run([sys.executable, "-m", "analysis.report", f"sessions={campaign}", f"out={out}",
                        f"sensitivity={nope}"], capture_output=True, text=True, cwd=Path(__file__).parents[2])
    assert r.returncode == 2, r.stderr[-2000:]
    assert r.stderr.strip().count("\n") == 0 and f"sensitivity={nope}: no such file" in r.stderr
    assert not (out / "results.json").exists() and not (out / "report.md").exists()


def test_help_opens_with_what_the_report_does(monkeypatch, capsys):
    from analysis.cli import report

    monkeypatch.setattr(sys, "argv", ["lsx-report", "--help", "sessions=somewhere"])
    with pytest.raises(SystemExit) as done:
        report()
    assert done.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith("python -m analysis.report [key=value ...]: ")
    assert "sessions=somewhere: the session files" in out and "\nsessions: somewhere\n" in out
