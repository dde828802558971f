"""Point-to-point motion under speed and acceleration limits, stepped at the world's rate.

A `LimitedMotion` is one actuated point in n dimensions (a stage's three axes, a gripper's jaw
opening, an arm's TCP position or rotation vector). Each step it steers its velocity toward the
target at no more than the commanded speed, slowing on the braking curve v = sqrt(2 a d), and
changes velocity by at most a * dt. That is a trapezoidal profile for a move from rest, and it
also handles a new target or a stop mid-move without a jump in velocity; the braking curve is
the discrete one, so a move ends on its target without overshoot. Scalar Python floats
keep a step to a few microseconds.
"""

from __future__ import annotations

import math


class LimitedMotion:
    """n-dimensional point with speed and acceleration limits.

    position, velocity: lists of n floats (units of the caller, e.g. mm and mm/s).
    """

    def __init__(self, start: list[float], max_accel: float) -> None:
        self.position = [float(v) for v in start]
        self.velocity = [0.0] * len(self.position)
        self.max_accel = float(max_accel)
        self.target: list[float] | None = None
        self.speed = 0.0
        self._stopping = False

    def command(self, target: list[float], speed: float, accel: float | None = None) -> None:
        """Start moving toward target at speed (accel defaults to the limit; capped at it)."""
        self.target = [float(v) for v in target]
        self.speed = float(speed)
        self.accel = min(float(accel), self.max_accel) if accel else self.max_accel
        self._stopping = False

    def stop(self) -> None:
        """Decelerate at the acceleration limit until at rest."""
        self.target = None
        self.accel = self.max_accel
        self._stopping = any(v != 0.0 for v in self.velocity)

    def halt(self) -> None:
        """Stop dead (a hard stop: jaws blocked by an object)."""
        self.target = None
        self._stopping = False
        self.velocity = [0.0] * len(self.position)

    @property
    def moving(self) -> bool:
        return self.target is not None or self._stopping

    def speed_now(self) -> float:
        return math.sqrt(sum(v * v for v in self.velocity))

    def step(self, dt: float) -> None:
        """Advance dt seconds."""
        if self.target is None and not self._stopping:
            return
        pos, vel = self.position, self.velocity
        n = len(pos)
        a_dt = self.accel * dt
        if self.target is None:  # braking to rest
            v = self.speed_now()
            if v <= a_dt:
                for i in range(n):
                    pos[i] += 0.5 * vel[i] * dt
                    vel[i] = 0.0
                self._stopping = False
                return
            scale = (v - a_dt) / v
            for i in range(n):
                nv = vel[i] * scale
                pos[i] += 0.5 * (vel[i] + nv) * dt
                vel[i] = nv
            return
        err = [self.target[i] - pos[i] for i in range(n)]
        dist = math.sqrt(sum(e * e for e in err))
        v_now = self.speed_now()
        if dist < 1e-12 or (v_now <= a_dt * (1 + 1e-9) and dist <= 0.5 * (v_now + a_dt) * dt):
            # One step from the target and slow enough to stop inside the acceleration limit: arrive.
            self.position = list(self.target)
            self.velocity = [0.0] * n
            self.target = None
            return
        # Discrete braking curve: after this step (trapezoidal integration) the point must still be
        # able to stop at the target, 0.5 (v + v') dt + v'^2 / (2 a) <= d.
        a = self.accel
        disc = a_dt * a_dt / 4.0 + 2.0 * a * dist - a * v_now * dt
        v_brake = -0.5 * a_dt + math.sqrt(disc) if disc > 0 else 0.0
        v_want = min(self.speed, max(v_brake, 0.0))
        dv = [err[i] / dist * v_want - vel[i] for i in range(n)]
        dv_norm = math.sqrt(sum(d * d for d in dv))
        if dv_norm > a_dt:
            s = a_dt / dv_norm
            dv = [d * s for d in dv]
        for i in range(n):
            nv = vel[i] + dv[i]
            pos[i] += 0.5 * (vel[i] + nv) * dt
            vel[i] = nv
