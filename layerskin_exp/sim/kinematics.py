"""Point-to-point motion under speed and acceleration limits, stepped at the world's rate.

A `LimitedMotion` is one actuated point in n dimensions (a stage's three axes, a gripper's jaw
opening, an arm's TCP position or rotation vector). Each step it steers its velocity toward the
target at no more than the commanded speed, slowing on the braking curve v = sqrt(2 a d), and
changes velocity by at most a * dt. That is a trapezoidal profile for a move from rest, and it
also handles a new target or a stop mid-move without a jump in velocity; the braking curve is
the discrete one, so a move ends on its target without overshoot. The step is compiled
(mechanics.motion_steps); `plan(m, dt)` runs m steps without changing the point and `commit`
adopts the state after one of them, so the world can run a stretch of steps at once and still
stop a motion at the step where a safety guard trips.
"""

from __future__ import annotations

import numpy as np

from layerskin_exp.sim import mechanics as mk


class LimitedMotion:
    """n-dimensional point with speed and acceleration limits (units of the caller, e.g. mm and
    mm/s). Its state is one float vector (mechanics' motion layout)."""

    def __init__(self, start: list[float], max_accel: float) -> None:
        self.n = n = len(start)
        self.max_accel = float(max_accel)
        self.state = np.zeros(mk.motion_size(n))
        self.state[mk.M_ACCEL] = self.max_accel
        self.state[mk.M_POS:mk.M_POS + n] = start
        self._p, self._v, self._g = slice(mk.M_POS, mk.M_POS + n), slice(mk.M_POS + n, mk.M_POS + 2 * n), \
            slice(mk.M_POS + 2 * n, mk.M_POS + 3 * n)

    # ---- state ---------------------------------------------------------------------------------
    @property
    def position(self) -> list[float]:
        return self.state[self._p].tolist()

    @position.setter
    def position(self, value: list[float]) -> None:
        self.state[self._p] = value

    @property
    def velocity(self) -> list[float]:
        return self.state[self._v].tolist()

    @property
    def moving(self) -> bool:
        return bool(self.state[mk.M_HAS_TARGET] or self.state[mk.M_STOPPING])

    # ---- commands ------------------------------------------------------------------------------
    def command(self, target: list[float], speed: float, accel: float | None = None) -> None:
        """Start moving toward target at speed (accel defaults to the limit; capped at it)."""
        st = self.state
        st[self._g] = target
        st[mk.M_HAS_TARGET], st[mk.M_STOPPING] = 1.0, 0.0
        st[mk.M_SPEED] = float(speed)
        st[mk.M_ACCEL] = min(float(accel), self.max_accel) if accel else self.max_accel

    def stop(self) -> None:
        """Decelerate at the acceleration limit until at rest."""
        st = self.state
        st[mk.M_HAS_TARGET] = 0.0
        st[mk.M_ACCEL] = self.max_accel
        st[mk.M_STOPPING] = float(bool(np.any(st[self._v] != 0.0)))

    def halt(self) -> None:
        """Stop dead (a hard stop: jaws blocked by an object)."""
        st = self.state
        st[mk.M_HAS_TARGET] = st[mk.M_STOPPING] = 0.0
        st[self._v] = 0.0

    # ---- stepping ------------------------------------------------------------------------------
    def plan(self, m: int, dt: float) -> np.ndarray:
        """(m, state size) the states after each of the next m steps of dt s; the point is unchanged."""
        out = np.empty((m, len(self.state)))
        if self.moving:
            mk.motion_steps(self.state, self.n, dt, m, out)
        else:
            out[:] = self.state
        return out

    def positions(self, plan: np.ndarray) -> np.ndarray:
        """(m, n) positions of a plan."""
        return plan[:, self._p]

    def commit(self, plan: np.ndarray, k: int) -> None:
        """Adopt the state after step k of a plan."""
        self.state[:] = plan[k]

    def step(self, dt: float) -> None:
        """Advance dt seconds."""
        self.commit(self.plan(1, dt), 0)
