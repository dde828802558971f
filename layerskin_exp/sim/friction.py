"""Stick-slip friction between the cover and the indenter, driven by the spacer's shear spring.

While the contact sticks, the cover moves with the indenter and the superficial layer is
displaced relative to the deep layer (the spacer shears): the tangential force is the spacer's
shear stiffness times that displacement, the torsional moment its torsional stiffness times the
relative rotation. When the force would exceed the static bound mu_s(t_stick) Fz, the cover
breaks away and slides until the spring has unloaded to the kinetic level minus an inertial
overshoot, then sticks again (a quasi-static, event-driven model: a slip of the light
superficial layer lasts far less than one 1 ms step). The static coefficient recovers from the
kinetic one with the time spent sticking (contact ageing), so slow drives give larger events.
Translation and rotation are bounded independently (no coupled friction limit surface).
Plain Python floats: this runs once per mechanical step.
"""

from __future__ import annotations

import math


class StickSlip:
    """Friction state of one contact: spacer shear, rotation and cumulative slip."""

    def __init__(self, mu_static: float, mu_kinetic: float, aging_s: float, overshoot: float):
        self.mu_s = self.mu_s_nominal = mu_static
        self.mu_k = self.mu_k_nominal = mu_kinetic
        self.aging_s = aging_s
        self.overshoot = overshoot
        self.reset()

    def set_surface_factor(self, factor: float) -> None:
        """Scale both coefficients from their nominal values (the surface state of one trial)."""
        if not (math.isfinite(factor) and factor > 0.0):
            raise ValueError(f"friction surface factor {factor!r} must be a finite number > 0")
        self.mu_s = self.mu_s_nominal * factor
        self.mu_k = self.mu_k_nominal * factor

    def reset(self) -> None:
        self.ux = 0.0  # superficial-layer shift relative to the deep layer, mm
        self.uy = 0.0
        self.theta = 0.0  # relative rotation, rad
        self.slip_x = 0.0  # cumulative slip of the cover relative to the indenter, mm
        self.slip_y = 0.0
        self.slip_rad = 0.0
        self.t_stick = 1e9  # long-aged contact at the start
        self.t_stick_rot = 1e9
        self.slipping = False

    def _mu_static(self, t_stick: float) -> float:
        if self.aging_s <= 0.0:
            return self.mu_s
        return self.mu_k + (self.mu_s - self.mu_k) * (1.0 - math.exp(-t_stick / self.aging_s))

    def _rest_level(self) -> float:
        # An undamped slip of a spring-loaded block swings as far below the kinetic level as the
        # static-kinetic gap above it; `overshoot` scales that for damping. Ending below the
        # kinetic level is what lets the contact re-stick, age and break away again.
        return max(self.mu_k - self.overshoot * (self.mu_s - self.mu_k), 0.0)

    def update(self, dt_s: float, dx_mm: float, dy_mm: float, dtheta_rad: float, fz_n: float,
               k_t_n_per_mm: float, k_r_nmm_per_rad: float, radius_mm: float) -> tuple[float, float, float]:
        """Advance by one step of indenter motion (dx, dy, dtheta) in the deep frame.

        Returns the tangential force (Fx, Fy) in N and torque in N mm the indenter applies.
        """
        if fz_n <= 0.0:  # no contact: the sheet springs back, nothing sticks
            self.ux = self.uy = self.theta = 0.0
            self.t_stick = self.t_stick_rot = 1e9
            self.slipping = False
            return 0.0, 0.0, 0.0
        slipping = False
        # translation
        ux, uy = self.ux + dx_mm, self.uy + dy_mm
        f = k_t_n_per_mm * math.hypot(ux, uy)
        mu_break = self._mu_static(self.t_stick)
        if f > mu_break * fz_n:
            scale = self._rest_level() * fz_n / f
            nx, ny = ux * scale, uy * scale
            self.slip_x += nx - ux
            self.slip_y += ny - uy
            ux, uy = nx, ny
            self.t_stick = 0.0
            slipping = True
        else:
            self.t_stick += dt_s
        self.ux, self.uy = ux, uy
        # rotation
        th = self.theta + dtheta_rad
        tq = k_r_nmm_per_rad * abs(th)
        mu_break = self._mu_static(self.t_stick_rot)
        bound = mu_break * fz_n * radius_mm
        if tq > bound and tq > 0.0:
            nth = th * self._rest_level() * fz_n * radius_mm / tq
            self.slip_rad += nth - th
            th = nth
            self.t_stick_rot = 0.0
            slipping = True
        else:
            self.t_stick_rot += dt_s
        self.theta = th
        self.slipping = slipping
        return k_t_n_per_mm * self.ux, k_t_n_per_mm * self.uy, k_r_nmm_per_rad * self.theta
