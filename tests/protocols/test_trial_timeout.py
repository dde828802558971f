"""trial_timeout_s is enforced: a trial that outlasts it is stopped (motion first) and kept as an
aborted file naming the limit; the run exits 1 and a rerun with room resumes it."""

from __future__ import annotations

import pytest

from layerskin_exp.log import load_session
from tests.protocols.conftest import run_cli

# a trial stopped at its timeout: beside the other real-time tests (tests/conftest.py)
pytestmark = pytest.mark.xdist_group("realtime")

CAL = ["positions.count=1", "press.repeats=1", "slide.repeats=1", "press.hold_s=0.05", "progress=false"]


def test_a_trial_past_its_timeout_is_stopped_and_kept_aborted(tmp_path, hydra_dirs):
    data = tmp_path / "data"
    r = run_cli("protocols.force_calibration", [*CAL, "trial_timeout_s=1", f"data_root={data}", *hydra_dirs], tmp_path)
    assert r.returncode == 1, r.stderr[-2000:]
    assert "trial_timeout_s=1 s" in r.stderr
    (partial,) = data.glob("force_calibration/*/*.partial")
    s = load_session(partial, warn=False)
    t = s.streams["skin"]["t_ns"]
    assert not s.complete and (t[-1] - t[0]) * 1e-9 < 1.2  # stopped at the limit, not at the trial's end
    assert s.outcome.startswith("aborted") and "trial_timeout_s=1 s" in s.outcome
    # the limit is run-only: the same design resumes with room and completes every trial
    r = run_cli("protocols.force_calibration", [*CAL, f"data_root={data}", *hydra_dirs], tmp_path)
    assert r.returncode == 0, r.stderr[-2000:]
    assert not list(data.glob("force_calibration/*/*.partial"))
