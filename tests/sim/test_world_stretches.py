"""The world runs its 1 kHz steps in compiled stretches: what happens must not depend on how the
protocol slices time. A guard trip inside a stretch rewinds to the tripping sample's step, and the
jaws' force stop is checked after every step, so the results equal a step-by-step run."""

import numpy as np
import pytest

from hardware import build_rig
from layerskin_exp.sim.kinematics import LimitedMotion
from tests.hardware.conftest import app_config


def _press_until_trip(tick_s: float, limit_n: float = 1.2):
    rig = build_rig(app_config(seed=5), "platform")
    rig.connect()
    rig.add_guard(lambda w: "over" if w.force_n[2] > limit_n else None)
    p = rig.platform.position_mm()
    rig.platform.move_to(np.array([p[0], p[1], -2.4]), 3.0)
    t = 0.0
    while t < 3.0:
        rig.clock.sleep(tick_s)
        t += tick_s
    wrench = rig.ft.read_available()
    stage = rig.platform.read_available()
    return rig, wrench, stage


def test_guard_trip_and_stop_do_not_depend_on_the_control_tick():
    # 1 ms ticks take one step per advance (no stretch to rewind); 37 ms ticks trip mid-stretch.
    fine, w_fine, s_fine = _press_until_trip(0.001)
    coarse, w_coarse, s_coarse = _press_until_trip(0.037)
    assert fine.tripped == coarse.tripped == "over"
    n = min(len(w_fine), len(w_coarse))
    assert n > 2000
    # the same samples, bit for bit: same steps, same noise, same trip, same braking afterwards
    assert [w.seq for w in w_fine[:n]] == [w.seq for w in w_coarse[:n]]
    np.testing.assert_array_equal(np.array([w.force_n for w in w_fine[:n]]),
                                  np.array([w.force_n for w in w_coarse[:n]]))
    first_over = next(i for i, w in enumerate(w_fine) if w.force_n[2] > 1.2)
    assert 0 < first_over < n
    m = min(len(s_fine), len(s_coarse))
    np.testing.assert_array_equal(np.array([s.position_mm for s in s_fine[:m]]),
                                  np.array([s.position_mm for s in s_coarse[:m]]))
    w_f, w_c = fine.extras["world"], coarse.extras["world"]
    assert not fine.platform.is_moving() and not coarse.platform.is_moving()
    assert w_f.scene.stage.position == w_c.scene.stage.position
    assert w_f.state.force_n[2] == w_c.state.force_n[2]


def _close_until_stalled(tick_s: float) -> float:
    # a soft force setting (the default 20 N minimum needs more travel than the series compliance gives)
    rig = build_rig(app_config(seed=2, gripper__force_min_n=4.0), "gripper")
    rig.connect()
    world = rig.extras["world"]
    limit = world.scene.grip_cfg.force_min_n  # force setting 0 %
    rig.gripper.move(0.0, 20.0, 0.0)  # close onto the rod until the force setting stops the jaws
    for _ in range(int(round(4.0 / tick_s))):
        rig.clock.sleep(tick_s)
    assert world.scene.stalled and not rig.gripper.is_moving()
    fz = world.state.force_n[2]
    # stopped on the step that reached the force setting: at most one step's load increment past it
    assert limit <= fz < limit + 0.05
    return world.scene.opening_mm


def test_jaw_force_stop_is_checked_every_step_whatever_the_tick():
    assert _close_until_stalled(0.001) == _close_until_stalled(0.05)


def test_motion_plan_leaves_the_point_and_commit_adopts_a_step():
    a = LimitedMotion([0.0, 0.0], 100.0)
    b = LimitedMotion([0.0, 0.0], 100.0)
    for m in (a, b):
        m.command([3.0, -4.0], 10.0)
    before = a.state.copy()
    plan = a.plan(40, 0.001)
    np.testing.assert_array_equal(a.state, before)
    for _ in range(25):
        b.step(0.001)
    a.commit(plan, 24)
    np.testing.assert_array_equal(a.state, b.state)
    # trapezoidal start: v = a t while accelerating
    assert np.hypot(*a.velocity) == pytest.approx(100.0 * 0.025, rel=1e-9)
