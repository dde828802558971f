"""The finite-element reference (layerskin_exp.sim.fem_reference) on a narrow section: what must
come out of the continuum solution (the walls carry the deep layer's load, the cover shears,
the film interface matters) does, and its comparison with the fast model can fail."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from layerskin_exp.sim import skin
from layerskin_exp.sim.config import SimConfig
from layerskin_exp.sim.fem_reference import compare as fc
from layerskin_exp.sim.fem_reference.model import Section, StackFE

SIM = SimConfig()


def _narrow(interface: str) -> StackFE:
    sec = replace(Section.from_sim(SIM, interface), width_mm=6.0)
    return StackFE(sec, wall_elems=2, void_elems=2, lattice_rows=3)


@pytest.fixture(scope="module")
def pressed():
    out = {}
    for bound in ("bonded", "unbonded"):
        fe = _narrow(bound)
        top = fe.height_mm + fe.sec.radius_mm
        fe.move_to(np.array([0.0, top - 0.3]), sticking=False, step_mm=0.1)
        out[bound] = (fe, fe.state())
    return out


def test_a_centred_press_is_symmetric_and_the_walls_carry_the_deep_load(pressed):
    fe, st = pressed["bonded"]
    assert st["fz_n_per_mm"] > 0 and abs(st["fx_n_per_mm"]) < 1e-6 * st["fz_n_per_mm"]
    assert st["contact_from_mm"] == pytest.approx(-st["contact_to_mm"], abs=1e-6)
    inner = np.abs(st["deep_x_mm"]) < 0.5 * fe.sec.width_mm - fe.sec.pitch_mm  # the rim is solid
    x, p = st["deep_x_mm"][inner], st["deep_kpa"][inner]
    wall = np.abs(x - np.round(x / fe.sec.pitch_mm) * fe.sec.pitch_mm) < 0.5 * fe.sec.wall_mm
    # the crossing walls carry the load; over the voids only the smeared walls along the section
    assert p[wall].mean() > 2 * abs(p[~wall]).mean()


def test_glued_films_make_a_stiffer_stack_than_free_ones(pressed):
    assert pressed["bonded"][1]["fz_n_per_mm"] > 1.2 * pressed["unbonded"][1]["fz_n_per_mm"]


def test_sticking_shear_loads_the_cap_and_the_cover_shears(pressed):
    fe, st0 = pressed["unbonded"]
    fe.stick_all_in_contact()
    fe.move_to(np.array([0.05, fe.centre[1]]), sticking=True, step_mm=0.05)
    st = fe.state()
    assert st["fx_n_per_mm"] > 0
    share = (st["cap_x_mm"] - st["sheet_x_under_cap_mm"]) / st["cap_x_mm"]
    assert 0.0 < share < 1.0  # the sheet follows the cap only partly: the cover is not rigid in shear


@pytest.fixture
def fresh_tables(monkeypatch):
    monkeypatch.setattr(skin, "_TABLE_CACHE", {})


def test_the_comparison_fails_on_a_lattice_three_times_too_soft(fresh_tables):
    rows, _ = fc.compare(SIM, bounds=("bonded",))
    assert any(r.passed for r in rows if r.metric == "line_load_at_depth")

    def soft(fsim):
        return replace(fsim, spacer=replace(fsim.spacer, modulus_kpa=fsim.spacer.modulus_kpa / 3.0))

    rows, _ = fc.compare(SIM, bounds=("bonded",), model_hook=soft)
    load = [r for r in rows if r.metric == "line_load_at_depth"]
    assert load and not any(r.passed for r in load)


def test_the_count_comparison_follows_the_spacers_shear_compliance(monkeypatch, fresh_tables):
    """The effective height read from counts is the fast model's shear coupling as the sensor
    sees it: a spacer ten times too stiff in shear moves it by more than the tolerance's width
    (so from anywhere inside the band to outside it)."""
    rows, _ = fc.compare(SIM, bounds=("bonded",))
    base = {(r.metric, r.load): r for r in rows if r.metric == "effective_height_counts"}
    law = skin.SpacerLaw.shear_stiffness_kpa_per_mm
    monkeypatch.setattr(skin.SpacerLaw, "shear_stiffness_kpa_per_mm", lambda self, c: 10.0 * law(self, c))
    monkeypatch.setattr(skin, "_TABLE_CACHE", {})
    rows, _ = fc.compare(SIM, bounds=("bonded",))
    heights = [r for r in rows if r.metric == "effective_height_counts"]
    lo, _ = fc.load_tolerances()["ratio"]["effective_height_counts"]
    assert heights and all(r.fast / base[(r.metric, r.load)].fast < lo for r in heights)
    assert not any(r.passed for r in heights)


def test_the_comparison_fails_on_a_cover_rigid_in_shear(monkeypatch, fresh_tables):
    """The sheet's share of the cap's travel and the tangential stiffness judge the cover's
    tangential path: with it removed (a cover rigid in shear, the sheet following the cap
    wholly) the rows that pass fail."""
    from layerskin_exp.sim import laminate

    def judged(rows):
        return [r for r in rows if r.metric in ("sheet_share_of_travel", "tangential_stiffness")]

    rows, _ = fc.compare(SIM, bounds=("bonded",))
    assert judged(rows) and all(r.passed for r in judged(rows))
    flank = laminate.PlateOnFoundation.flank
    monkeypatch.setattr(laminate.PlateOnFoundation, "flank", lambda self, sol: (flank(self, sol)[0], 0.0))
    monkeypatch.setattr(skin, "_TABLE_CACHE", {})
    rows, _ = fc.compare(SIM, bounds=("bonded",))
    share = [r for r in rows if r.metric == "sheet_share_of_travel"]
    assert share and not any(r.passed for r in share)


def test_the_comparison_fails_on_a_cover_squeezed_over_a_fixed_width(monkeypatch, fresh_tables):
    """Contact width and peak contact pressure judge the cover's compression stiffness: taking
    its shape factor over a fixed 2 mm (the cap's radius scale) instead of the contact's own
    width makes it ~10x too stiff, and the width rows fail."""
    from layerskin_exp.sim import contact

    rows, _ = fc.compare(SIM, bounds=("bonded",))
    widths = [r for r in rows if r.metric == "contact_width"]
    assert widths and all(r.passed for r in widths)
    monkeypatch.setattr(contact, "contact_confinement_mm", lambda *a: 2.0)
    monkeypatch.setattr(skin, "_TABLE_CACHE", {})
    rows, _ = fc.compare(SIM, bounds=("bonded",))
    widths = [r for r in rows if r.metric == "contact_width"]
    assert widths and not any(r.passed for r in widths)


def _fast_values(rows) -> dict:
    out: dict = {}
    for r in rows:
        out.setdefault(r.metric, []).append(r.fast)
    return out


def _inject_fixed_cover_width(monkeypatch):
    from layerskin_exp.sim import contact

    monkeypatch.setattr(contact, "contact_confinement_mm", lambda *a: 2.0)


def _inject_lost_flank(monkeypatch):
    from layerskin_exp.sim import laminate

    flank = laminate.PlateOnFoundation.flank

    def no_flank_pressure(self, sol):
        resp, k = flank(self, sol)
        return laminate.CoupleResponse(resp.w_mm, 0.0 * resp.contact_kpa, 0.0 * resp.foundation_kpa), k

    monkeypatch.setattr(laminate.PlateOnFoundation, "flank", no_flank_pressure)


def _inject_stiff_spacer_shear(monkeypatch):
    law = skin.SpacerLaw.shear_stiffness_kpa_per_mm
    monkeypatch.setattr(skin.SpacerLaw, "shear_stiffness_kpa_per_mm", lambda self, c: 10.0 * law(self, c))


def _stiff_sheet(fsim):
    return replace(fsim, sheet=replace(fsim.sheet, film_modulus_mpa=100.0 * fsim.sheet.film_modulus_mpa))


# physical error -> (how it is injected: a monkeypatch or a design hook, the metrics that must see it)
INJECTIONS = {
    "cover squeezed over a fixed 2 mm": (_inject_fixed_cover_width, None, ("contact_width", "peak_superficial_kpa")),
    "flank pressure lost": (_inject_lost_flank, None, ("superficial_offset_counts_mm", "superficial_asymmetry_counts")),
    "lattice 10x too stiff in shear": (_inject_stiff_spacer_shear, None, ("tangential_stiffness",
                                                                          "effective_height_counts")),
    "sheet 100x too stiff in bending": (None, _stiff_sheet, ("peak_deep_taxel_kpa", "effective_height_rise",
                                                             "interlayer_shift_counts_mm", "deep_cop_counts_mm")),
}


@pytest.fixture(scope="module")
def fast_base():
    skin._TABLE_CACHE.clear()
    rows, _ = fc.compare(SIM, bounds=("bonded",))
    return _fast_values(rows)


@pytest.mark.parametrize("error", list(INJECTIONS))
def test_each_fem_metric_sees_the_error_it_names(error, fast_base, monkeypatch, fresh_tables):
    """A fast model that matched the FEM exactly (at the band's centre) would fail the check
    under the injected error: the fast value moves by more than the tolerance (difference
    metrics) or by a factor outside [lo, hi] (ratio metrics), at one load at least. Which error
    each metric catches is what layerskin_exp/sim/fem_reference/tolerances.yaml and validate's notes say."""
    patch, hook, metrics = INJECTIONS[error]
    if patch is not None:
        patch(monkeypatch)
    rows, _ = fc.compare(SIM, bounds=("bonded",), model_hook=hook)
    got = _fast_values(rows)
    tol = fc.load_tolerances()
    for metric in metrics:
        base, inj = np.asarray(fast_base[metric]), np.asarray(got[metric])
        if metric in tol["difference"]:
            assert (np.abs(inj - base) > tol["difference"][metric]).any(), (metric, base, inj)
        else:
            lo, hi = tol["ratio"][metric]
            factor = inj / base
            assert ((factor < lo) | (factor > hi)).any(), (metric, base, inj)
