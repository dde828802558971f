"""A resumed campaign is the campaign that would have run: each trial's content and date follow
from its identity, not from the trials run before it in the same process (issues 31, 32)."""

from __future__ import annotations

import time

import numpy as np
import pytest
from mcap.reader import make_reader
from omegaconf import OmegaConf

import protocols.calibration as calibration
from hardware import build_rig
from layerskin_exp.config import ConfigError
from layerskin_exp.log import load_session
from protocols import runner
from protocols.calibration import campaign_root, plan_trials, run_campaign
from protocols.runner import trial_slot_s
from tests.protocols.conftest import compose_app

# Four trials at two positions: a trial runs after others, first after a resume, or alone.
CAMPAIGN = ["positions.count=2", "press.repeats=1", "slide.repeats=1", "press.hold_s=0.05", "progress=false"]
START = "2026-01-05T09:00:00Z"
START_NS = 1_767_603_600 * 10**9  # START on the Unix epoch


def _campaign(data, stop_at: int | None = None, start_time: str | None = START, extra=()):
    """Run the campaign into data on a fresh simulated rig; with stop_at, Ctrl-C arrives at the
    first tick of that trial (it is closed aborted and the run ends)."""
    start = "null" if start_time is None else start_time
    cfg, typed = compose_app("force_calibration", [*CAMPAIGN, f"data_root={data}", f"sim.rig.start_time={start}",
                                                   *extra])
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
        # and dated the same: at a fixed start, every message is the same, log time included
        assert _messages(whole / f"{name}.mcap") == _messages(resumed / f"{name}.mcap"), name


def _messages(path) -> list[tuple[str, int, int, bytes]]:
    """(topic, log time, publish time, payload) of every message, in file order."""
    with open(path, "rb") as f:
        return [(ch.topic, m.log_time, m.publish_time, m.data) for _, ch, m in make_reader(f).iter_messages(
            log_time_order=False)]


def _log_span_ns(path) -> tuple[int, int]:
    """(first, last) MCAP log time of a session file, read from the messages themselves."""
    with open(path, "rb") as f:
        times = [msg.log_time for _, _, msg in make_reader(f).iter_messages()]
    return min(times), max(times)


def test_trials_are_dated_from_the_run_start_and_follow_each_other_in_run_order(tmp_path):
    typed, folder = _campaign(tmp_path)
    spans = [_log_span_ns(folder / f"{t.name}.mcap") for t in plan_trials(typed)]
    slot_ns = trial_slot_s(1, typed.trial_timeout_s) * 1e9
    for k, (first, last) in enumerate(spans):
        assert START_NS + k * slot_ns <= first <= last < START_NS + (k + 1) * slot_ns
    assert all(a[1] < b[0] for a, b in zip(spans, spans[1:], strict=False))


def test_without_a_start_time_a_run_is_dated_when_it_starts(tmp_path):
    before = time.time_ns()
    typed, folder = _campaign(tmp_path, start_time=None, extra=["positions.count=1", "slide.repeats=0"])
    after = time.time_ns()
    (trial,) = plan_trials(typed)
    first, last = _log_span_ns(folder / f"{trial.name}.mcap")
    assert before <= first <= after and last - first < typed.trial_timeout_s * 1e9


@pytest.mark.parametrize("value", ["yesterday", "2026-01-05", "2026-01-05T09:00:00", "1900-01-01T00:00:00Z"])
def test_a_start_time_that_is_not_a_utc_instant_is_refused_naming_it(value):
    with pytest.raises(ConfigError, match=r"sim\.rig\.start_time=.*(UTC date and time|years)"):
        compose_app("force_calibration", [f"sim.rig.start_time={value}"])
