"""The force ceiling under a latched stop condition, and the guard state every end of a platform
move leaves for the next one (the closed-form fake rig, tests/protocols/fake_rig.py)."""

from __future__ import annotations

import numpy as np
import pytest

from layerskin_exp.log import load_session
from layerskin_exp.types import Wrench
from protocols.calibration import PlatformControl, run_campaign
from protocols.config import ForceCalibrationConfig
from protocols.runner import run_trial
from protocols.safety import Safety
from tests.protocols.fake_rig import platform_rig

META = {"config": {}, "backend": "fake"}


def _cfg(tmp_path, **kw) -> ForceCalibrationConfig:
    cfg = ForceCalibrationConfig(hardware={}, skin={}, data_root=str(tmp_path), progress=False)
    cfg.positions.count, cfg.press.repeats, cfg.slide.repeats = 1, 1, 0
    for k, v in kw.items():
        obj, _, attr = k.rpartition(".")
        setattr(cfg if not obj else getattr(cfg, obj), attr, v)
    return cfg


def _wrench(rig, fz_n: float) -> Wrench:
    t = rig.clock.now_ns()
    return Wrench(np.array([0.0, 0.0, fz_n]), np.zeros(3), 0, t, t)


def test_the_force_limit_trips_while_a_slow_zone_trip_is_latched():
    rig = platform_rig()
    rig.connect()
    safety = Safety(ForceCalibrationConfig(hardware={}, skin={}).safety, rig)
    safety.platform_speed_mm_s = 2.0  # a fast move under way
    zone = rig.check_guards(_wrench(rig, 5.7))
    assert zone.startswith("slow_zone") and rig.tripped == zone
    rig.platform.move_to(np.array([0.0, 0.0, -1.0]), 0.3)  # the crawl the zone leads to
    stops = len(rig.platform.stopped_at_ns)
    assert rig.guard_reason(_wrench(rig, 7.9)).startswith("force_limit")  # the simulator's probe sees it
    assert rig.check_guards(_wrench(rig, 7.9)).startswith("force_limit: Fz=7.900 N")
    assert rig.tripped.startswith("force_limit") and len(rig.platform.stopped_at_ns) == stops + 1
    assert not rig.platform.is_moving()
    rig.check_guards(_wrench(rig, 7.5))
    assert [r[:23] for r, _ in rig.take_ceiling_events()] == ["force_limit: Fz=7.900 N", "force_limit: Fz=7.500 N"]
    # acknowledging the zone's stop does not clear the limit's trip that replaced it
    assert rig.clear_trip(zone) is None and rig.tripped.startswith("force_limit")


def test_a_sample_over_the_limit_under_a_latched_stop_makes_the_trial_not_plain_complete(tmp_path, monkeypatch):
    # A press aimed at 5.8 N enters the slow zone (0.9 x 6 N) and stops; while the stage stands with
    # the zone's trip latched, two samples over 6 N arrive (a burst read late). Each is a safety
    # event; the trial ends with the force limit, retracts, and is not recorded plain complete.
    cfg = _cfg(tmp_path, **{"press.target_normal_n": 5.8})
    rig = platform_rig(k_n_per_mm=4.0)
    rig.connect()
    wait = PlatformControl.wait_stopped
    fed = []

    def wait_with_a_burst(self):
        if rig.tripped is not None and rig.tripped.startswith("slow_zone") and not fed:
            fed.extend(rig.check_guards(_wrench(rig, fz)) for fz in (7.9, 7.2))
        return wait(self)

    monkeypatch.setattr(PlatformControl, "wait_stopped", wait_with_a_burst)
    (result,) = run_campaign(cfg, rig, META)
    assert fed and all(r.startswith("force_limit") for r in fed)
    assert result.stop_reason == "force_limit"
    assert result.outcome.startswith("complete (safety stop: force_limit: Fz=7.900 N exceeds 6.0 N; ")
    assert result.outcome.endswith("2 samples over the limit)")
    s = load_session(result.path, warn=False)
    assert s.outcome == result.outcome
    ev = s.streams["events"]
    safety = [m for k, m in zip(ev["kind"], ev["message"], strict=True) if k == "safety"]
    assert [m[:23] for m in safety] == ["force_limit: Fz=7.900 N", "force_limit: Fz=7.200 N"]
    assert "retract" in ev["message"] and rig.tripped is None  # the retract acknowledged it


def _in_a_trial(tmp_path, rig, cfg, body, late=None):
    """Run body(ctl) in a trial; late(ctl), if given, runs at the start of every wait_stopped."""
    ctl = PlatformControl(rig, Safety(cfg.safety, rig), cfg)
    if late is not None:
        wait = ctl.wait_stopped
        ctl.wait_stopped = lambda: (late(ctl), wait())

    def run(log):
        ctl.bind(log)
        body(ctl)

    return run_trial(rig, tmp_path / "t.mcap", {"t": 0}, META, run)


BOTTOM = np.array([0.0, 0.0, -2.0])
UP = np.array([0.0, 0.0, 1.0])


def _tick_stop(wrenches):
    return "stop_here" if wrenches and max(w.force_n[2] for w in wrenches) >= 2.0 else None


@pytest.mark.parametrize("path", ["stop", "stop_target", "target_reached", "slow_zone", "arrived"])
def test_every_end_of_a_move_leaves_the_guard_clear_for_the_next_move(tmp_path, path):
    # Each way a press or a slide move can end, with a sample read late while the stage brakes
    # (5.7 N: in the slow zone, under the limit), then the next move (what the slide or the lift
    # does): it must start, the stage must count as standing, and nothing may stay latched. The
    # "stop" path used to leave the late sample's slow-zone trip latched ("guard tripped (slow_zone:
    # ...); acknowledge it before moving again"); "stop_target", a press ended at the tick with its
    # stage guard reading the target late, left "target_reached" latched the same way.
    cfg = _cfg(tmp_path)
    rig = platform_rig(k_n_per_mm=4.0, stop_latency_s=0.02)
    rig.connect()
    ends = []
    deferred: list = []

    def late(ctl):
        if path == "stop_target":  # the stage guard's samples are checked only now (a busy host)
            check = type(rig).check_guards
            for w, stream in deferred:
                check(rig, w, stream)
            deferred.clear()
            rig.check_guards = lambda w, stream="ft": check(rig, w, stream)
        else:
            rig.check_guards(_wrench(rig, 5.7))

    def body(ctl):
        if path == "stop":
            ends.append(ctl.move(BOTTOM, 2.0, _tick_stop))
        elif path == "stop_target":
            rig.check_guards = lambda w, stream="ft": deferred.append((w, stream))
            ends.append(ctl.press(3.0, stop_reason_on_target=False))
        elif path == "target_reached":
            ends.append(ctl.press(3.0, stop_reason_on_target=False))
        elif path == "slow_zone":
            ends.append(ctl.press(5.8, stop_reason_on_target=False))
        else:
            ends.append(ctl.move(np.array([0.0, 0.0, 0.5]), 2.0))
        assert ctl.safety.platform_speed_mm_s == 0.0
        assert rig.tripped is None
        ends.append(ctl.move(UP, 5.0))

    result = _in_a_trial(tmp_path, rig, cfg, body, late)
    assert result.outcome == "complete"
    expected = {"stop": "stop_here", "stop_target": "target_reached", "target_reached": "target_reached",
                "slow_zone": "target_reached", "arrived": None}[path]
    assert ends == [expected, None]
