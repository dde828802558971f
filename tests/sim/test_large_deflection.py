"""The sheet in large deflection (`sim.sheet.large_deflection`, laminate.PlateOnFoundation's
membrane): its forces are its strain energy's gradient, it carries no net load of its own, it
vanishes at a light touch and stiffens a deep press, and the first angular mode's operator gives a
rigid tilt and the couple's moment back as statics requires."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from layerskin_exp.sim.config import load_sim
from layerskin_exp.sim.contact import _solver

SIM = load_sim(["sheet.interface=bonded", "sheet.large_deflection=true", "sheet.wrinkling=false"])  # smooth
LINEAR = load_sim(["sheet.interface=bonded", "sheet.large_deflection=false"])


def _energy(plate, w, u):
    """The membrane's strain energy written out afresh (laminate.PlateOnFoundation.membrane_forces)."""
    h = plate.step
    b = np.diff(w) / h
    rm = (np.arange(len(w) - 1) + 0.5) * h
    e_r = np.diff(u) / h + 0.5 * b * b
    e_t = 0.5 * (u[:-1] + u[1:]) / rm
    nu = plate.poisson
    return float((plate._seg_area * 0.5 * plate.membrane * (e_r**2 + 2 * nu * e_r * e_t + e_t**2)).sum())


def _state(plate, seed=0):
    rng = np.random.default_rng(seed)
    n = len(plate.x)
    return 0.8 * np.exp(-plate.x**2 / 30.0) + 0.01 * rng.standard_normal(n), 2e-3 * rng.standard_normal(n)


def _mismatch(plate, forces) -> float:
    """Largest relative error of `forces(w, u)` -> (gradient, Hessian) against central differences
    of the energy (gradient) and of the gradient (Hessian columns), at a few degrees of freedom."""
    w, u = _state(plate)
    n = len(w)
    f, k = forces(w, u)
    z, eps, worst = np.concatenate([w, u]), 1e-7, 0.0
    for i in (0, 3, 40, 150, n + 2, n + 90):
        zp, zm = z.copy(), z.copy()
        zp[i] += eps
        zm[i] -= eps
        fd = (_energy(plate, zp[:n], zp[n:]) - _energy(plate, zm[:n], zm[n:])) / (2 * eps)
        col = (forces(zp[:n], zp[n:])[0] - forces(zm[:n], zm[n:])[0]) / (2 * eps)
        worst = max(worst, abs(fd - f[i]) / max(abs(f).max(), 1e-12),
                    float(np.abs(col - k[:, i].toarray().ravel()).max() / abs(k).max()))
    return worst


@pytest.fixture(scope="module")
def plate():
    return _solver(SIM, "hemisphere")


def test_the_membrane_forces_are_its_energy_gradient_and_hessian(plate):
    def forces(w, u):
        f, k, _ = plate.membrane_forces(w, u)
        return f, k
    assert _mismatch(plate, forces) < 1e-5


def test_a_wrong_membrane_tangent_is_caught(plate):
    """The check above fails on a tangent without the membrane force's pull on the slope."""
    n = len(plate.x)

    def forces(w, u):
        f, k, (n_r, _) = plate.membrane_forces(w, u)
        geo = plate._seg_area * n_r / plate.step**2  # the geometric term, taken out again
        seg = np.arange(n - 1)
        rows = np.concatenate([seg, seg + 1, seg, seg + 1])
        cols = np.concatenate([seg, seg + 1, seg + 1, seg])
        vals = np.concatenate([-geo, -geo, geo, geo])
        return f, k + sp.csr_matrix((vals, (rows, cols)), shape=k.shape)
    assert _mismatch(plate, forces) > 1e-3


def test_the_membrane_carries_no_net_load_and_the_press_balances(plate):
    w, u = _state(plate)
    f, _, _ = plate.membrane_forces(w, u)
    assert abs(f[: len(w)].sum()) < 1e-9 * np.abs(f).max()
    # the press's lattice carries its load as well as the linear plate's does at the same depth
    # (the finite-difference bending operator loses a little on its own): the membrane adds no loss
    def loss(p):
        sol = p.solve(1.2)
        return abs(float(sol.foundation_kpa @ p.area) * 1e-3 / p.load(sol) - 1.0), sol

    with_membrane, sol = loss(plate)
    # within what the plate's finite-difference bending operator loses on its own (0.6 % linear)
    assert with_membrane <= 0.01
    assert with_membrane <= loss(_solver(LINEAR, "hemisphere"))[0] + 1e-4
    n_r, _ = sol.membrane_n_per_mm
    assert n_r[0] > 0.0  # the dish's centre is pulled taut


def test_a_light_touch_is_the_linear_plate_and_a_deep_press_is_stiffer(plate):
    linear = _solver(LINEAR, "hemisphere")
    light = plate.load(plate.solve(0.02)) / linear.load(linear.solve(0.02))
    deep = plate.load(plate.solve(1.5)) / linear.load(linear.solve(1.5))
    assert light == pytest.approx(1.0, abs=0.01)
    assert deep > 1.2


def test_the_first_mode_gives_a_rigid_tilt_and_the_couple_back(plate):
    sol = plate.solve(1.5)
    geometric = plate._operator_m1(sol) - plate._operator_m1(None)
    tilt = geometric @ plate.x
    bend = geometric @ (plate.x * np.exp(-plate.x / 3.0))
    on = plate.on_pad & (plate.x > 0) & (plate.x < plate.pad_radius - 1.0)
    assert np.abs(tilt[on]).max() < 1e-4 * np.abs(bend[on]).max()
    share = 0.5
    resp = plate.couple(sol, share)
    moment = plate.first_moment(resp.foundation_kpa) - plate.first_moment(resp.contact_kpa)
    assert moment == pytest.approx(1.0 - share, rel=0.02)


def test_the_rod_stays_a_linear_plate():
    assert _solver(SIM, "rod").membrane == 0.0
    assert _solver(LINEAR, "hemisphere").membrane == 0.0


# --- off the pad's centre: the tables are solved for a pad centred on the contact, and the
# membrane spreads a 3 N press past the sides of the real one (frame_kernels._pad_fold)
OFF_CENTRE = load_sim(["sheet.large_deflection=true", "readout.noise_counts=0", "readout.scan_jitter_ms=0"])
PRESSES_MM = [(0.0, 3.0), (4.0, 3.0), (8.0, 3.0), (11.0, -6.0)]


@pytest.fixture(scope="module")
def wide_model():
    from layerskin_exp.config import SkinConfig
    from layerskin_exp.sim.skin import SkinModel

    model = SkinModel(OFF_CENTRE, SkinConfig(), "hemisphere", np.random.default_rng(0))
    model.reuse_maps = False  # each press is a fresh state, never the last one's hold
    model.unloaded = model.mech_state()  # before any contact: each press starts from it
    return model


def _press(model, xy, fz_n=3.0):
    depth = float(np.interp(fz_n, model.tab.load, model.tab.delta_mm))
    model.restore_mech_state(model.unloaded)
    return model.step_many(np.array([0.0]), np.array([[xy[0], xy[1], -depth]]), np.zeros(1))[0]


@pytest.mark.parametrize("xy", PRESSES_MM)
def test_an_off_centre_press_carries_its_load_where_statics_puts_it(wide_model, xy):
    """The deep sheet's pressure over the pad (the numpy reference's fields, a 0.1 mm grid) carries
    the press's F_z within 1 % and its force CoP lies at the contact within 0.05 mm. Without the
    sheet's rigid-body answer to what the profile puts past the sides, a 3 N press 4 mm from the
    centre kept 0.86 of its load on the pad and its CoP 1.45 mm towards the centre (8 mm: 0.71, 3.2 mm)."""
    from layerskin_exp.sim import mechanics as mk
    from layerskin_exp.sim.reference import ReferenceSkin

    rec = _press(wide_model, xy)
    g = np.arange(-13.0 + 0.05, 13.0, 0.1)
    x, y = np.meshgrid(g, g)
    _, deep, _ = ReferenceSkin(wide_model).signed_fields(rec, x, y)
    force = float(deep.sum()) * 0.01 * 1e-3
    assert force / rec[mk.S_FZ] == pytest.approx(1.0, abs=0.01)
    assert float((deep * x).sum() / deep.sum()) == pytest.approx(xy[0], abs=0.05)
    assert float((deep * y).sum() / deep.sum()) == pytest.approx(xy[1], abs=0.05)


@pytest.mark.parametrize("xy", PRESSES_MM)
def test_the_kernel_folds_as_the_reference_does(wide_model, xy):
    """The compiled maps against the numpy reference's Gauss means, off the centre where the fold
    acts: within 0.1 % of each layer's peak."""
    from layerskin_exp.sim.reference import ReferenceSkin

    rec = _press(wide_model, xy)
    got = wide_model._maps([wide_model.state_of(rec)])[0]
    want = ReferenceSkin(wide_model).maps(rec[None, :])[0]
    for layer in range(2):
        assert np.abs(got[layer] - want[layer]).max() <= 1e-3 * want[layer].max()


def test_the_stretched_sheets_rim_is_in_hoop_compression_past_the_wrinkling_load():
    """validate's record of the membrane at 3 N: the rim's hoop force is compressive, beyond the
    glued sheet's wrinkling load 2 sqrt(D k) (Hetenyi), written out here from the design."""
    import math

    from layerskin_exp.sim.physics_checks import membrane_record

    rec = membrane_record(LINEAR)["membrane_hoop_at_3n_large_deflection"]["glued"]
    k = LINEAR.spacer.lattice_modulus_kpa * 1e-3 / LINEAR.spacer.thickness_mm
    assert rec["wrinkling_threshold_n_per_mm"] == pytest.approx(2 * math.sqrt(LINEAR.sheet.rigidity_n_mm * k), rel=0.01)
    assert rec["hoop_min_n_per_mm"] < -rec["wrinkling_threshold_n_per_mm"] < 0
    assert rec["over_threshold_from_to_mm"][1] > rec["over_threshold_from_to_mm"][0] > 2.0


def test_the_bending_plate_answers_near_a_side_unfolded():
    """The small-deflection sheet is not folded (its influence length is a fraction of the pad):
    its kernel maps at a press 2 mm from a side are the numpy reference's, which adds nothing."""
    from layerskin_exp.config import SkinConfig
    from layerskin_exp.sim.reference import ReferenceSkin
    from layerskin_exp.sim.skin import SkinModel

    sim = load_sim(["sheet.large_deflection=false", "readout.noise_counts=0", "readout.scan_jitter_ms=0"])
    model = SkinModel(sim, SkinConfig(), "hemisphere", np.random.default_rng(0))
    model.unloaded = model.mech_state()
    assert model._params["fold_sides"] == 0.0
    rec = _press(model, (11.0, -6.0))
    got = model._maps([model.state_of(rec)])[0]
    want = ReferenceSkin(model).maps(rec[None, :])[0]
    for layer in range(2):
        assert np.abs(got[layer] - want[layer]).max() <= 1e-3 * want[layer].max()


WRINKLING = load_sim(["sheet.interface=bonded", "sheet.large_deflection=true", "sheet.wrinkling=true"])


def _relaxed_energy(plate, w, u):
    """The wrinkling membrane's energy written out afresh (laminate._tension_field): plane stress
    while neither force is compressed past the cap; past it, that force stays at -cap (the energy
    grows by -cap times the strain beyond where it reached the cap), the other direction a strip."""
    h, c, nu, cap = plate.step, plate.membrane, plate.poisson, plate.wrinkle
    b = np.diff(w) / h
    rm = (np.arange(len(w) - 1) + 0.5) * h
    e_r = np.diff(u) / h + 0.5 * b * b
    e_t = 0.5 * (u[:-1] + u[1:]) / rm

    def taut(er, et):
        return 0.5 * c * (er**2 + 2 * nu * er * et + et**2)

    n_r, n_t = c * (e_r + nu * e_t), c * (e_t + nu * e_r)
    strip = c * (1 - nu * nu)
    corner = -cap / (c * (1 + nu))  # both forces at -cap
    et_star, er_star = -cap / c - nu * e_r, -cap / c - nu * e_t
    hoop = (n_t < -cap) & (strip * e_r - nu * cap >= -cap)
    radial = (n_r < -cap) & (strip * e_t - nu * cap >= -cap) & ~hoop
    both = ((n_t < -cap) | (n_r < -cap)) & ~hoop & ~radial
    energy = np.where(hoop, taut(e_r, et_star) - cap * (e_t - et_star),
                      np.where(radial, taut(er_star, e_t) - cap * (e_r - er_star),
                               np.where(both, taut(corner, corner) - cap * (e_r - corner + e_t - corner),
                                        taut(e_r, e_t))))
    return float((plate._seg_area * energy).sum()), hoop | radial | both


@pytest.fixture(scope="module")
def wrinkled():
    """The wrinkling sheet at a state of the smooth one pressed 1.5 mm, whose rim is in hoop
    compression far past the cap."""
    smooth = _solver(SIM, "hemisphere")
    sol = smooth.solve(1.5)
    return _solver(WRINKLING, "hemisphere"), sol.w_mm, sol.u_mm


def _relaxed_mismatch(plate, w, u, forces) -> float:
    n = len(w)
    f, k = forces(w, u)
    _, slack = _relaxed_energy(plate, w, u)
    seg = int(np.flatnonzero(slack).min()) + 5  # inside the wrinkled ring
    z, eps, worst = np.concatenate([w, u]), 1e-7, 0.0
    for i in (3, 40, seg, seg + 1, n + 2, n + seg, n + seg + 1):
        zp, zm = z.copy(), z.copy()
        zp[i] += eps
        zm[i] -= eps
        fd = (_relaxed_energy(plate, zp[:n], zp[n:])[0] - _relaxed_energy(plate, zm[:n], zm[n:])[0]) / (2 * eps)
        col = (forces(zp[:n], zp[n:])[0] - forces(zm[:n], zm[n:])[0]) / (2 * eps)
        worst = max(worst, abs(fd - f[i]) / max(abs(f).max(), 1e-12),
                    float(np.abs(col - k[:, i].toarray().ravel()).max() / abs(k).max()))
    return worst


def test_the_wrinkling_membranes_forces_are_its_relaxed_energys_gradient_and_hessian(wrinkled):
    plate, w, u = wrinkled
    _, slack = _relaxed_energy(plate, w, u)
    assert slack.sum() > 20  # the state reaches well into the wrinkled ring

    def forces(w, u):
        f, k, _ = plate.membrane_forces(w, u)
        return f, k
    assert _relaxed_mismatch(plate, w, u, forces) < 1e-5


def test_a_wrinkled_ring_with_the_smooth_sheets_tangent_is_caught(wrinkled):
    """The check above fails when the wrinkled ring keeps plane stress's stiffness (the forces
    capped, the tangent not)."""
    plate, w, u = wrinkled
    smooth = _solver(SIM, "hemisphere")

    def forces(w, u):
        return plate.membrane_forces(w, u)[0], smooth.membrane_forces(w, u)[1]
    assert _relaxed_mismatch(plate, w, u, forces) > 1e-3


def test_the_wrinkled_sheet_carries_no_compression_past_its_cap_and_is_the_smooth_one_where_taut(wrinkled):
    import math

    plate, w, u = wrinkled
    k = WRINKLING.spacer.lattice_modulus_kpa * 1e-3 / WRINKLING.spacer.thickness_mm
    assert plate.wrinkle == pytest.approx(2 * math.sqrt(WRINKLING.sheet.rigidity_n_mm * k), rel=1e-9)
    n_r, n_t = plate.membrane_forces(w, u)[2]
    s_r, s_t = _solver(SIM, "hemisphere").membrane_forces(w, u)[2]
    assert n_t.min() >= -plate.wrinkle - 1e-12 and n_r.min() >= -plate.wrinkle - 1e-12
    assert s_t.min() < -2 * plate.wrinkle  # the smooth sheet, at the same state, does not (-1.05 N/mm)
    taut = (s_t > -plate.wrinkle) & (s_r > -plate.wrinkle)
    assert np.allclose(n_r[taut], s_r[taut]) and np.allclose(n_t[taut], s_t[taut])
    # solved, the wrinkling sheet's press balances as the smooth one's does, and its centre stays taut
    sol = plate.solve(1.2)
    assert abs(float(sol.foundation_kpa @ plate.area) * 1e-3 / plate.load(sol) - 1.0) <= 0.01
    n_r, n_t = sol.membrane_n_per_mm
    assert n_r[0] > 0.0 and n_t.min() >= -plate.wrinkle - 1e-9
