"""Physics of the simulated skin: equilibrium, friction, contact size, against closed forms."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import quad

from layerskin_exp.config import SkinConfig
from layerskin_exp.sim.config import SimConfig, SpacerConfig
from layerskin_exp.sim.skin import SkinModel, _chord, stack_states
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


def test_normal_force_matches_direct_integration_of_the_spacer_law():
    m = model()
    law = SpacerLaw(m.sim.spacer)
    radius = m.sim.contact.hemisphere_radius_mm
    for z in (-1.0, -2.0, -2.2):
        st = press(model(), z)
        delta = -z
        a = math.sqrt(2 * radius * delta - delta**2)
        f = quad(lambda r, d=delta: float(law.pressure_kpa(d - (radius - math.sqrt(radius**2 - r**2)))) * 2 * math.pi * r,
                 0.0, a, limit=200)[0] * 1e-3
        assert st.force_n[2] == pytest.approx(f, rel=0.02)


def test_force_rises_monotonically_with_indentation_and_contact_grows():
    """Winkler contact: the loaded zone is the geometric intersection a = sqrt(2 R d - d^2),
    blurred by the cover/shear-coupling length; its area grows with load even though the
    densified centre takes an ever larger share of the force."""
    forces, areas = [], []
    radius = 2.5
    for z in np.linspace(-0.5, -2.25, 8):
        m = model()
        st = press(m, z)
        sup, _ = m.pressure_fields(stack_states([st]))
        cell_area = (SKIN.electrode_mm / m.sim.contact.quad_points) ** 2  # area per quadrature point, roughly
        loaded = float(np.count_nonzero(sup[0] > 0.5)) * cell_area * (SKIN.pitch_mm / SKIN.electrode_mm) ** 2
        a = math.sqrt(2 * radius * -z - z * z)
        assert math.pi * (a - 0.3) ** 2 < loaded < math.pi * (a + 2.0) ** 2
        forces.append(st.force_n[2])
        areas.append(loaded)
    assert np.all(np.diff(forces) > 0)
    assert np.all(np.diff(areas) > 0)


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
        assert f_sup == pytest.approx(fz * 24.0 / m.sim.spacer.width, rel=0.05)
    assert f_deep == pytest.approx(f_sup, rel=0.08)


def test_moment_balance_deep_cop_shift_times_fz_equals_shear_times_height():
    m = model(lattice_contrast=0.0)
    states = [m.step(k * 1e-3, np.array([0.0, 0.0, -2.2])) for k in range(20)]
    for k in range(60):  # slide 0.6 mm diagonally, stays stuck
        states.append(m.step(0.02 + k * 1e-3, np.array([0.01 * (k + 1), 0.005 * (k + 1), -2.2])))
    st = states[-1]
    fz, ft = st.force_n[2], st.force_n[:2]
    assert not st.slipping and np.hypot(*ft) > 0.3
    sup, deep = m.pressure_maps([st])
    c_contact_deep = st.contact_xy_mm + st.surface_shift_mm
    h = float(m.stack_height_mm(st.indentation_mm))
    shift = cop(deep[0]) - c_contact_deep
    np.testing.assert_allclose(shift * fz, ft * h, rtol=0.1, atol=0.02)
    # superficial CoP stays at the contact on its own layer; the inter-layer shift opposes the shear
    np.testing.assert_allclose(cop(sup[0]), st.contact_xy_mm, atol=0.05)
    dc = cop(sup[0]) - cop(deep[0])
    np.testing.assert_allclose(dc, -(st.surface_shift_mm + ft * h / fz), rtol=0.1, atol=0.03)
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


def test_rod_torsion_friction_torque_bound_and_rotational_slip():
    m = model("rod", k=20.0)
    states = [m.step(k * 1e-3, np.array([0.0, 0.0, -2.3])) for k in range(50)]
    for k in range(3000):
        yaw = math.radians(25.0) * min(k / 2000.0, 1.0)
        states.append(m.step(0.05 + k * 1e-3, np.array([0.0, 0.0, -2.3]), yaw))
    st = states[-1]
    half = m.sim.spacer.width / 2
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
