"""Physics of the simulated skin: equilibrium, friction, contact size, against closed forms."""

from __future__ import annotations

import math

import numpy as np
import pytest

from layerskin_exp.config import SkinConfig
from layerskin_exp.sim.config import SimConfig, SpacerConfig
from layerskin_exp.sim.skin import SkinModel, _chord
from layerskin_exp.sim.spacer import SpacerLaw

SKIN = SkinConfig()
PITCH_AREA_MM2 = SKIN.pitch_mm**2


def model(kind="hemisphere", seed=0, k=None, **spacer):
    sim = SimConfig(seed=seed, spacer=SpacerConfig(**spacer))
    return SkinModel(sim, SKIN, kind, np.random.default_rng(seed), support_stiffness_n_per_mm=k)


def cop(p):
    xs = SKIN.taxel_centres_mm()
    tot = p.sum()
    return np.array([p.sum(axis=0) @ xs / tot, p.sum(axis=1) @ xs / tot])


def pca_angle(p):
    xs = SKIN.taxel_centres_mm()
    x, y = np.meshgrid(xs, xs)
    w = p / p.sum()
    mx, my = (w * x).sum(), (w * y).sum()
    cxx, cyy, cxy = (w * (x - mx) ** 2).sum(), (w * (y - my) ** 2).sum(), (w * (x - mx) * (y - my)).sum()
    return 0.5 * math.atan2(2 * cxy, cxx - cyy)


def press(m, z, xy=(0.0, 0.0), yaw=0.0):
    return m.step(0.0, np.array([xy[0], xy[1], z]), yaw)


@pytest.mark.xfail(strict=True, reason="issue 21 — fails since the cover/lattice physics change 1ccfa6c; the tables solve each row with the cover squeezed over the contact's own width, the plate here with the cap's radius")
def test_normal_force_is_what_the_lattice_carries_under_the_laminate():
    """Equilibrium of the laminate: the force on the indenter equals the integral of the
    lattice's pressure under the sheet (the sheet only redistributes it), and the lattice
    carries the pressure of its own compression (SpacerLaw) everywhere."""
    from layerskin_exp.sim.contact import _solver

    m = model()
    plate = _solver(m.sim, "hemisphere")
    law = SpacerLaw(m.sim.spacer)
    w = None
    for delta in (0.5, 1.5, 2.0, 2.2):
        sol = plate.solve(delta, w)
        w = sol.w_mm
        f_contact = plate.load(sol)
        f_lattice = float(sol.foundation_kpa @ plate.area) * 1e-3
        assert f_contact == pytest.approx(f_lattice, rel=0.01)
        pressed = (sol.w_mm > 0) & plate.on_pad
        np.testing.assert_allclose(sol.foundation_kpa[pressed], law.pressure_kpa(sol.w_mm[pressed]), rtol=1e-9)
        st = press(model(), -delta)
        assert st.force_n[2] == pytest.approx(f_contact, rel=0.01)


def test_force_rises_monotonically_with_indentation_and_contact_grows():
    """The sheet spreads the load: force, contact radius and the deep layer's loaded area all
    grow with the indentation, the contact stays inside the indenter's geometric intersection
    a = sqrt(2 R d - d^2) (the sheet is stiffer than the cover: it does not wrap the cap), and
    the deep layer is loaded over far more than the contact."""
    forces, radii, deep_areas = [], [], []
    radius = 2.5
    for z in np.linspace(-0.5, -2.25, 8):
        m = model()
        st = press(m, z)
        _, deep = m.pressure_maps([st])
        a = float(np.interp(-z, m.tab.delta_mm, m.tab.contact_halfwidth_mm))
        assert 0 < a < math.sqrt(2 * radius * -z - z * z)
        forces.append(st.force_n[2])
        radii.append(a)
        deep_areas.append(np.count_nonzero(deep[0] > 2.0) * PITCH_AREA_MM2)  # taxels above 2 kPa
        assert deep_areas[-1] > math.pi * a * a
    assert np.all(np.diff(forces) > 0)
    assert np.all(np.diff(radii) >= 0) and radii[-1] > radii[0]
    assert np.all(np.diff(deep_areas) >= 0) and deep_areas[-1] > deep_areas[0]


@pytest.mark.parametrize("kind,z", [("hemisphere", -2.2), ("rod", -2.0)])
def test_force_balance_superficial_and_deep(kind, z):
    m = model(kind)
    st = press(m, z, xy=(0.75, -0.75))
    sup, deep = m.pressure_maps([st])
    fz = st.force_n[2]
    assert fz > 1.0
    f_sup = sup.sum() * PITCH_AREA_MM2 * 1e-3
    f_deep = deep.sum() * PITCH_AREA_MM2 * 1e-3
    if kind == "hemisphere":
        assert f_sup == pytest.approx(fz, rel=0.05)
    else:  # the rod's line load also falls on the border outside the 24 mm array
        assert f_sup == pytest.approx(fz * 24.0 / m.sim.spacer.width_mm, rel=0.05)
    assert f_deep == pytest.approx(f_sup, rel=0.08)


@pytest.mark.xfail(strict=True, reason="issue 21 — fails since the cover/lattice physics change 1ccfa6c; 0.6 mm of travel now gives 0.28 N (< 0.3 N) and the flank's moment is not in this balance")
def test_moment_balance_of_the_shear_is_shared_by_lattice_and_indenter():
    """The shear's couple F_t H about the deep plane is balanced by the lattice's pressure (the
    deep CoP moves along the shear) and by the contact pressure on the stage-held indenter (the
    superficial CoP moves against it): the two moments add up to F_t H exactly. What the deep
    layer reads is the first-order moment balance F_t H = F_z shift less the indenter's share."""
    from layerskin_exp.sim.contact import _solver

    m = model(lattice_contrast=0.0)
    plate = _solver(m.sim, "hemisphere")
    sol = plate.solve(2.0)
    resp = plate.couple(sol)
    lattice_share = plate.first_moment(resp.foundation_kpa)
    indenter_share = -plate.first_moment(resp.contact_kpa)
    assert lattice_share + indenter_share == pytest.approx(1.0, abs=0.01)
    assert 0.2 < lattice_share < 1.0 and indenter_share > 0
    states = [m.step(k * 1e-3, np.array([0.0, 0.0, -2.0])) for k in range(20)]
    for k in range(60):  # slide 0.6 mm diagonally, stays stuck
        states.append(m.step(0.02 + k * 1e-3, np.array([0.01 * (k + 1), 0.005 * (k + 1), -2.0])))
    st = states[-1]
    fz, ft = st.force_n[2], st.force_n[:2]
    assert not st.slipping and np.hypot(*ft) > 0.3
    sup, deep = m.pressure_maps([st])
    h = float(m.stack_height_mm(st.indentation_mm))
    shift_deep = cop(deep[0]) - (st.contact_xy_mm + st.surface_shift_mm)
    shift_sup = cop(sup[0]) - st.contact_xy_mm
    unit = ft / np.hypot(*ft)
    # along the shear and not beyond the whole moment; against it on the superficial layer
    assert 0.3 * lattice_share < (shift_deep @ unit) * fz / (np.hypot(*ft) * h) < 1.05
    assert (shift_sup @ unit) < 0
    # the inter-layer shift opposes the shear: spacer shear plus both layers' moment shifts
    dc = cop(sup[0]) - cop(deep[0])
    assert (dc @ unit) < -(st.surface_shift_mm @ unit)
    # and the lattice pattern only perturbs it
    m2 = model()
    _, deep2 = m2.pressure_maps([st])
    assert np.linalg.norm(cop(deep2[0]) - cop(deep[0])) < 0.3


def test_shear_stiffness_rises_with_compression():
    ks = []
    for z in (-1.8, -2.1, -2.25):
        m = model()
        m.step(0.0, np.array([0.0, 0.0, z]))
        st = m.step(0.001, np.array([0.05, 0.0, z]))
        assert not st.slipping
        ks.append(st.force_n[0] / st.surface_shift_mm[0])
    assert ks[0] < ks[1] < ks[2]


def test_slide_friction_bound_and_stick_slip_events():
    m = model()
    mu = m.sim.cover.friction
    states = [m.step(k * 1e-3, np.array([0.0, 0.0, -2.2])) for k in range(50)]
    for k in range(4000):  # 8 mm at 2 mm/s
        states.append(m.step(0.05 + k * 1e-3, np.array([0.002 * k, 0.0, -2.2])))
    ft = np.array([np.hypot(*s.force_n[:2]) for s in states])
    fz = np.array([s.force_n[2] for s in states])
    assert np.all(ft <= mu * fz + 1e-9)
    slipping = np.array([s.slipping for s in states])
    onsets = np.flatnonzero(slipping[1:] & ~slipping[:-1])
    assert len(onsets) >= 3  # stick-slip, not one steady slide
    assert ft.max() > 0.9 * mu * fz.max()
    slip = states[-1].slip_mm
    assert slip[0] < -1.0 and abs(slip[1]) < 1e-9  # the cover slid back relative to the indenter


@pytest.mark.xfail(strict=True, reason="issue 21 — fails since the cover/lattice physics change 1ccfa6c; 25 deg of twist no longer reaches rotational slip with the cover's torsional compliance in series")
def test_rod_torsion_friction_torque_bound_and_rotational_slip():
    m = model("rod", k=20.0)
    states = [m.step(k * 1e-3, np.array([0.0, 0.0, -2.3])) for k in range(50)]
    for k in range(3000):
        yaw = math.radians(25.0) * min(k / 2000.0, 1.0)
        states.append(m.step(0.05 + k * 1e-3, np.array([0.0, 0.0, -2.3]), yaw))
    st = states[-1]
    half = m.sim.spacer.width_mm / 2
    chords = [_chord(0.0, 0.0, s.indenter_yaw_rad, half) for s in states]
    radius = np.array([(s1 * s1 + s2 * s2) / (2 * (s2 - s1)) for s1, s2 in chords])  # mean |s| on the line
    tq = np.array([abs(s.torque_z_nmm) for s in states])
    fz = np.array([s.force_n[2] for s in states])
    assert np.all(tq <= m.sim.cover.friction * fz * radius + 1e-9)
    assert st.slip_rad < -0.05
    slipping = np.array([s.slipping for s in states])
    assert np.count_nonzero(slipping[1:] & ~slipping[:-1]) >= 2
    # mid-rotation, while sticking: the deep line turns with the gripper beyond the superficial
    # one by more than the spacer's twist (the traction's local moments add to it)
    mid = next(s for s in states[1000:] if not s.slipping and abs(s.surface_rotation_rad) > 0.02)
    sup, deep = m.pressure_maps([mid])
    diff = pca_angle(deep[0]) - pca_angle(sup[0])
    assert np.sign(diff) == np.sign(mid.torque_z_nmm)
    assert abs(diff) > abs(mid.surface_rotation_rad)


def test_series_support_compliance():
    k = 5.0
    m = model(k=k)
    st = press(m, -3.0)
    assert st.indentation_mm + st.force_n[2] / k == pytest.approx(3.0, abs=1e-3)
    assert st.indentation_mm < 3.0
