"""Re-running the report on the same sessions gives the same numbers, bit for bit."""

import json
import sys
from pathlib import Path

import torch

from analysis.config import AnalysisConfig, CnnConfig, SlipConfig
from analysis.report import run_report

sys.path.insert(0, str(Path(__file__).parent))
from synthetic import write_campaign, write_sensitivity_result  # noqa: E402


def _numbers(out: Path) -> dict:
    data = json.loads((out / "results.json").read_text())
    data.pop("timing_s")  # wall-clock times are the one thing allowed to differ
    return data


def test_two_runs_on_the_same_sessions_give_identical_results(tmp_path):
    sessions = write_campaign(tmp_path / "sessions", n_positions=4, grip_depths=(6, 12), trials=2)

    def cfg():  # T-s5 feeds the force-based slip cues, the preload and the live detector
        return AnalysisConfig(cnn=CnnConfig(configurations=["T-s5"], max_epochs=2, patience=1, max_train_windows=512),
                              slip=SlipConfig(n_thresholds=8, offset_step_s=0.05), figures=False, progress=False)

    sens = write_sensitivity_result(tmp_path / "sensitivity.json")
    outer = torch.get_num_threads()
    run_report(sessions, tmp_path / "a", cfg(), sensitivity=sens)
    torch.set_num_threads(2)  # the caller's thread setting must not leak into the numbers
    try:
        run_report(sessions, tmp_path / "b", cfg(), sensitivity=sens)
    finally:
        torch.set_num_threads(outer)
    a, b = _numbers(tmp_path / "a"), _numbers(tmp_path / "b")
    assert a["slip"] and a["force"]["T-s5"] and a["slip_causal"] and a["characterization"]["sensitivity_bands"]
    assert a == b
    assert (tmp_path / "a" / "report.md").read_text() == (tmp_path / "b" / "report.md").read_text()
    assert torch.get_num_threads() == outer and not torch.are_deterministic_algorithms_enabled()
