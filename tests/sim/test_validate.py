"""The physics validation suite (layerskin_exp.sim.validate): every check on the default design
passes. Each check states its physical expectation; see the module for the closed forms."""

from __future__ import annotations

import pytest

from layerskin_exp.sim import validate as v
from layerskin_exp.sim.config import SimConfig

SIM = SimConfig()


@pytest.mark.parametrize("check", [v.lateral_stiffness, v.plate_on_winkler_closed_form, v.vertical_stiffness,
                                   v.preload_tangent_stiffness, v.moment_equilibrium])
def test_closed_form_and_equilibrium_checks(check):
    c = check(SIM)
    assert c.passed, f"{c.name}: {c.value:.4g} outside [{c.lo}, {c.hi}] ({c.expectation})"


def test_lattice_pressure_stays_in_the_fsr_range_at_preload():
    c, contact_peak = v.lattice_pressure_at_preload(SIM)
    assert c.passed, c
    assert contact_peak > c.value * SIM.fsr.saturation_kpa  # the contact is more concentrated than the lattice


def test_friction_bounds_the_shear_in_stick_and_carries_it_in_slip():
    for c in v.friction_bound(SIM):
        assert c.passed, f"{c.name}: {c.value:.4g}"


def test_most_slides_reach_the_shear_stop_and_the_force_limit_trips_near_6n():
    frac, fz, reasons = v.slide_outcomes(SIM, n=12)
    assert frac.passed and fz.passed, (frac, fz, reasons)


def test_interlayer_shift_and_effective_height():
    shift, height, heights = v.interlayer_shift_and_height(SIM)
    assert shift.passed and height.passed, (shift, height, heights)


def test_gain_spread_and_the_position_spread_it_leaves():
    taxel, position, _ = v.response_spread(SIM, n_positions=16)
    assert taxel.passed and position.passed, (taxel, position)


def test_overrides_reach_the_design():
    sim = v.load_sim(["sim.spacer.modulus=20", "sheet.bonded=false"])
    assert sim.spacer.modulus == 20 and sim.sheet.bonded is False
    assert sim.sheet.rigidity_n_mm < SIM.sheet.rigidity_n_mm
