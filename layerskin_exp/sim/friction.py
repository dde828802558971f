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
The step itself is compiled (mechanics.friction_update, run inside the contact kernel); this
class holds the coefficients and the state vector it works on.
"""

from __future__ import annotations

import math

import numpy as np

from layerskin_exp.sim import mechanics as mk


class StickSlip:
    """Friction of one contact: coefficients `params` [mu_s, mu_k, aging_s, overshoot] and state
    `state` (spacer shear ux, uy mm and rotation theta rad, cumulative slip, stick times)."""

    def __init__(self, mu_static: float, mu_kinetic: float, aging_s: float, overshoot: float):
        self.mu_s_nominal, self.mu_k_nominal = mu_static, mu_kinetic
        self.params = np.array([mu_static, mu_kinetic, aging_s, overshoot], dtype=float)
        self.state = np.zeros(mk.FRICTION_SIZE)
        self.reset()

    @property
    def mu_s(self) -> float:
        return float(self.params[0])

    @property
    def mu_k(self) -> float:
        return float(self.params[1])

    def set_surface_factor(self, factor: float) -> None:
        """Scale both coefficients from their nominal values (the surface state of one trial)."""
        if not (math.isfinite(factor) and factor > 0.0):
            raise ValueError(f"friction surface factor {factor!r} must be a finite number > 0")
        self.params[0] = self.mu_s_nominal * factor
        self.params[1] = self.mu_k_nominal * factor

    def reset(self) -> None:
        """Unloaded, long-aged contact: no shear, no slip."""
        self.state[:] = 0.0
        self.state[mk.F_T_STICK] = self.state[mk.F_T_STICK_ROT] = 1e9
