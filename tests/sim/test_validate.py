"""The physics validation suite (layerskin_exp.sim.physics_checks): each check passes on the default
design and fails when the physical error it names is injected into the simulated side (a
perturbed parameter or a disabled mechanism), so none of them is a check that cannot fail."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from layerskin_exp.sim import laminate, skin
from layerskin_exp.sim import physics_checks as v
from layerskin_exp.sim.config import SimConfig, load_sim

SIM = SimConfig()


@pytest.fixture
def fresh_tables(monkeypatch):
    """Contact tables built inside the test stay there (an injected error must not leak)."""
    monkeypatch.setattr(skin, "_TABLE_CACHE", {})


def test_every_check_names_the_error_it_catches():
    for check in (v.lateral_stiffness(SIM), v.plate_on_winkler_closed_form(SIM), v.moment_equilibrium(SIM),
                  v.gain_spread(SIM), *v.friction_bound(SIM)):
        assert check.catches, check.name


def test_lateral_stiffness_catches_a_pad_shear_stiffness_not_the_honeycombs(monkeypatch, fresh_tables):
    assert v.lateral_stiffness(SIM).passed
    law = skin.SpacerLaw.shear_stiffness_kpa_per_mm
    monkeypatch.setattr(skin.SpacerLaw, "shear_stiffness_kpa_per_mm", lambda self, c: 2.0 * law(self, c))
    assert not v.lateral_stiffness(SIM).passed


def test_plate_closed_form_catches_a_wrong_bending_operator(monkeypatch):
    assert v.plate_on_winkler_closed_form(SIM).passed
    lap = laminate.laplacian
    monkeypatch.setattr(laminate, "laplacian", lambda kind, n, step: 1.2 * lap(kind, n, step))
    assert not v.plate_on_winkler_closed_form(SIM).passed


def test_vertical_stiffness_catches_a_lattice_far_too_stiff(fresh_tables):
    assert v.vertical_stiffness(SIM).passed
    stiff = replace(SIM, spacer=replace(SIM.spacer, modulus_kpa=4.0 * SIM.spacer.modulus_kpa))
    assert not v.vertical_stiffness(SIM, model_sim=stiff).passed


def test_a_stretching_sheets_vertical_stiffness_is_judged_in_its_small_deflection_limit(fresh_tables):
    """The closed form is the bending plate's: a design with the membrane on is judged with it off,
    so the check still fails on the lattice far too stiff."""
    ld = replace(SIM, sheet=replace(SIM.sheet, large_deflection=True, wrinkling=True))
    assert v.vertical_stiffness(ld).value == pytest.approx(v.vertical_stiffness(SIM).value, rel=1e-9)
    stiff = replace(ld, spacer=replace(ld.spacer, modulus_kpa=4.0 * ld.spacer.modulus_kpa))
    assert not v.vertical_stiffness(ld, model_sim=stiff).passed


def test_moment_equilibrium_catches_the_indenters_share_lost(monkeypatch):
    assert v.moment_equilibrium(SIM).passed
    couple = laminate.PlateOnFoundation.couple

    def without_indenter(self, sol, lattice_share):
        r = couple(self, sol, lattice_share)
        return laminate.CoupleResponse(r.w_mm, 0.0 * r.contact_kpa, r.foundation_kpa)

    monkeypatch.setattr(laminate.PlateOnFoundation, "couple", without_indenter)
    assert not v.moment_equilibrium(SIM).passed


def test_friction_checks_catch_a_contact_holding_too_much_or_sliding_too_freely(monkeypatch):
    """The checks' slide starts light enough to slip (physics_checks.FRICTION_PRELOAD_N); one
    that never slips fails both rather than judging a stuck contact."""
    assert all(c.passed for c in v.friction_bound(SIM))
    real = skin.StickSlip
    monkeypatch.setattr(skin, "StickSlip", lambda mu_s, mu_k, *a: real(1.3 * mu_s, mu_k, *a))
    assert not v.friction_bound(SIM)[0].passed  # holds past static friction
    monkeypatch.setattr(skin, "StickSlip", lambda mu_s, mu_k, *a: real(mu_s, 0.7 * mu_k, *a))
    assert not v.friction_bound(SIM)[1].passed  # slides carrying less than kinetic friction
    monkeypatch.setattr(skin, "StickSlip", lambda mu_s, mu_k, *a: real(20.0 * mu_s, 20.0 * mu_k, *a))
    assert not any(c.passed for c in v.friction_bound(SIM))  # never slips within the slide


def test_gain_check_catches_a_spread_not_as_configured():
    assert v.gain_spread(SIM).passed
    wide = replace(SIM, fsr=replace(SIM.fsr, gain_cv=0.3))
    assert not v.gain_spread(SIM, model_sim=wide).passed


def test_slides_use_the_protocols_thresholds_and_are_reported_not_checked():
    shear_n, limit_n = v.protocol_stops()
    assert (shear_n, limit_n) == (2.0, 6.0)  # conf/force_calibration.yaml
    rec = v.slide_record(SIM, n=4)
    assert sum(rec["slide_stop_reasons"].values()) == 4 and rec["slide_largest_fz_n"] > 0


def test_overrides_reach_the_design():
    sim = load_sim(["sim.spacer.modulus_kpa=20", "sheet.interface=bonded"])
    assert sim.spacer.modulus_kpa == 20 and sim.sheet.interface == "bonded"
    assert sim.sheet.rigidity_n_mm == pytest.approx(SIM.sheet.sandwich_rigidity_n_mm)


def test_checks_on_the_readout_use_counts_and_the_features_cop():
    rec = v.shift_and_height_record(SIM)
    assert set(rec["effective_height_counts_mm_by_fz"]) == {1.0, 3.0, 5.0}
    assert np.isfinite(rec["interlayer_shift_counts_mm_per_n_at_3n"])


def test_the_slide_stops_are_the_calibration_protocols():
    """validate's calibration-style slide stops where the protocol does: its stops are held to the
    composed, validated calibration config (the core cannot compose the protocols' schema)."""
    import protocols.config  # noqa: F401 - stores the calibration app's schemas
    from layerskin_exp.config import compose

    cfg = compose("force_calibration")
    assert v.protocol_stops() == (cfg.slide.shear_stop_n, cfg.safety.max_normal_force_n)
