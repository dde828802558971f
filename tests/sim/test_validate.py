"""The physics validation suite (layerskin_exp.sim.validate): every check on the default design
passes. Each check states its physical expectation; see the module for the closed forms."""

from __future__ import annotations

import numpy as np
import pytest

from layerskin_exp.sim import validate as v
from layerskin_exp.sim.config import SimConfig

SIM = SimConfig()


@pytest.mark.parametrize("check", [v.lateral_stiffness, v.plate_on_winkler_closed_form, v.vertical_stiffness,
                                   v.moment_equilibrium])
def test_closed_form_and_equilibrium_checks(check):
    c = check(SIM)
    assert c.passed, f"{c.name}: {c.value:.4g} outside [{c.lo}, {c.hi}] ({c.expectation})"


def test_friction_held_films_lie_between_the_bonded_and_free_sheets():
    stiff, k3 = v.preload_tangent_stiffness(SIM)
    peak, deep_kpa, contact_kpa = v.lattice_pressure_at_preload(SIM)
    assert stiff.passed and peak.passed, (stiff, peak)
    assert 0.05 < stiff.value < 0.95 and 0.05 < peak.value < 0.95  # strictly between: partial action
    assert contact_kpa > deep_kpa  # the contact is more concentrated than the lattice under it


def test_films_stick_under_the_cap_and_slip_beyond_it():
    """Friction carries the sandwich's shear flow where the pressure is high and the flow low
    (the contact's centre), not a few millimetres out where the lattice pressure is small."""
    from layerskin_exp.sim.contact import _solver

    plate = _solver(SIM, "hemisphere")
    sol = plate.solve(2.0)
    eta = sol.composite
    assert eta[0] == pytest.approx(1.0, abs=0.02)
    assert float(np.interp(4.0, plate.x, eta)) < 0.1
    assert SIM.sheet.rigidity_n_mm < float(np.interp(0.3, plate.x, sol.rigidity_n_mm)) <= SIM.sheet.sandwich_rigidity_n_mm


def test_friction_bounds_the_shear_in_stick_and_carries_it_in_slip():
    for c in v.friction_bound(SIM):
        assert c.passed, f"{c.name}: {c.value:.4g}"


def test_most_slides_reach_the_shear_stop_and_the_force_limit_trips_near_6n():
    frac, fz, reasons = v.slide_outcomes(SIM, n=12)
    assert frac.passed and fz.passed, (frac, fz, reasons)


def test_interlayer_shift_and_effective_height():
    shift, height, heights = v.interlayer_shift_and_height(SIM)
    assert shift.passed and height.passed, (shift, height, heights)
    rises = v.height_rises_with_load(heights)
    assert rises.passed, (rises, heights)


def test_gain_spread_and_the_position_spread_it_leaves():
    taxel, position, _ = v.response_spread(SIM, n_positions=16)
    assert taxel.passed and position.passed, (taxel, position)


def test_overrides_reach_the_design():
    sim = v.load_sim(["sim.spacer.modulus=20", "sheet.interface=bonded"])
    assert sim.spacer.modulus == 20 and sim.sheet.interface == "bonded"
    assert sim.sheet.rigidity_n_mm == pytest.approx(SIM.sheet.sandwich_rigidity_n_mm)
