"""A resumed campaign is the campaign that would have run: each trial's content follows from its
identity, not from the trials run before it in the same process (issue 31)."""

from __future__ import annotations

import numpy as np
import pytest
from omegaconf import OmegaConf

import protocols.calibration as calibration
from hardware import build_rig
from layerskin_exp.log import load_session
from protocols import runner
from protocols.calibration import campaign_root, plan_trials, run_campaign
from tests.protocols.conftest import compose_app

# Four trials at two positions: a trial runs after others, first after a resume, or alone.
CAMPAIGN = ["positions.count=2", "press.repeats=1", "slide.repeats=1", "press.hold_s=0.05", "progress=false"]


def _campaign(data, stop_at: int | None = None):
    """Run the campaign into data on a fresh simulated rig; with stop_at, Ctrl-C arrives at the
    first tick of that trial (it is closed aborted and the run ends)."""
    cfg, typed = compose_app("force_calibration", [*CAMPAIGN, f"data_root={data}"])
    calls = []
    real_run_trial = calibration.run_trial

    def run_trial(rig, path, labels, metadata, body, **kw):
        calls.append(path)
        if len(calls) - 1 == stop_at:
            def interrupted(log, body=body):
                runner.request_termination("interrupted (Ctrl-C)")
                body(log)
            return real_run_trial(rig, path, labels, metadata, interrupted, **kw)
        return real_run_trial(rig, path, labels, metadata, body, **kw)

    metadata = {"config": OmegaConf.to_container(cfg, resolve=True), "backend": "sim"}
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(calibration, "run_trial", run_trial)
        with build_rig(cfg, "platform") as rig:
            try:
                run_campaign(typed, rig, metadata)
            except runner.Terminated:
                assert stop_at is not None
            finally:
                runner._termination.clear()  # the request was this test's; the rerun runs trials again
    return typed, campaign_root(typed, metadata["config"])


def _content(path) -> dict:
    """What a trial recorded, apart from when: skin counts, wrenches, stage, events (order kept)."""
    s = load_session(path, warn=False)
    ev = s.streams["events"]
    return {"outcome": s.outcome, "labels": s.labels,
            "skin": (s.streams["skin"]["superficial"], s.streams["skin"]["deep"], s.streams["skin"]["seq"]),
            "force_n": s.streams["wrench"]["force_n"], "torque_nm": s.streams["wrench"]["torque_nm"],
            "stage_mm": s.streams["stage"]["position_mm"],
            "events": list(zip(ev["kind"], ev["message"], strict=True))}


def _assert_same(a: dict, b: dict, name: str) -> None:
    assert a.keys() == b.keys()
    for key in a:
        x, y = a[key], b[key]
        if isinstance(x, tuple):
            assert all(np.array_equal(u, v) for u, v in zip(x, y, strict=True)), f"{name}: {key} differs"
        elif isinstance(x, np.ndarray):
            assert x.shape == y.shape and np.array_equal(x, y), f"{name}: {key} differs"
        else:
            assert x == y, f"{name}: {key} differs"


def test_an_interrupted_and_resumed_campaign_equals_an_uninterrupted_one(tmp_path):
    typed, whole = _campaign(tmp_path / "whole")
    _, resumed = _campaign(tmp_path / "resumed", stop_at=2)
    assert (resumed / "pos001_press0.mcap.partial").is_file()  # the trial in progress, kept aborted
    _campaign(tmp_path / "resumed")
    names = [t.name for t in plan_trials(typed)]
    assert sorted(p.name for p in resumed.glob("*.mcap*")) == sorted(f"{n}.mcap" for n in names)
    for name in names:
        _assert_same(_content(whole / f"{name}.mcap"), _content(resumed / f"{name}.mcap"), name)
