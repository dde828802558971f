"""Physics of the simulated skin: equilibrium, friction, contact size, against closed forms."""

from __future__ import annotations

import math

import numpy as np
import pytest

from layerskin_exp.config import SkinConfig
from layerskin_exp.sim.config import SimConfig, SpacerConfig
from layerskin_exp.sim.laminate import edge_fade_mm
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


def test_normal_force_is_what_the_lattice_carries_under_the_laminate():
    """Equilibrium of the laminate: the force on the indenter equals the integral of the
    lattice's pressure under the sheet (the sheet only redistributes it), and the lattice
    carries the pressure of its own compression (SpacerLaw) everywhere. Solved as the tables
    solve each row (the cover squeezed over the contact's own width, `cover_n_per_mm3`), at
    table rows, and the skin model pressed there reads the same force."""
    from layerskin_exp.sim.contact import _solver

    m = model()
    tab = m.tab
    plate = _solver(m.sim, "hemisphere")
    law = SpacerLaw(m.sim.spacer)
    w = None
    for target in (0.5, 1.5, 2.0, 2.2):
        k = int(np.argmin(np.abs(tab.delta_mm - target)))
        delta = float(tab.delta_mm[k])
        plate.k_cover = float(tab.cover_n_per_mm3[k])
        sol = plate.solve(delta, w)
        w = sol.w_mm
        f_contact = plate.load(sol)
        f_lattice = float(sol.foundation_kpa @ plate.area) * 1e-3
        assert f_contact == pytest.approx(f_lattice, rel=0.01)
        assert f_contact == pytest.approx(tab.load[k], rel=0.01)
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


@pytest.mark.parametrize("lean", [True, False])
def test_moment_balance_of_the_sheared_hemisphere_stack(lean):
    """Statics of the sheared stack under the hemisphere (the rod's: test_shear_mechanism): stuck
    after a 0.8 mm diagonal slide at 2 mm, the lattice's signed pressure on the deep plane, over
    the model's pad (the disc of the pad's area), balances the contact's load where it now sits
    and the shear at the cover's height, int p (x - x_feet) dA = F_z (x_load - x_feet) + F_t H
    along both axes, within 3 %. Without the sheet's travel in the deep pattern's position (the
    pattern left at the columns' feet, the moment F_z u with no route) the deep plane misses F_z u."""
    from dataclasses import replace

    from layerskin_exp.sim import mechanics as mk
    from layerskin_exp.sim.laminate import pad_radius_mm
    from layerskin_exp.sim.reference import ReferenceSkin

    sim = SimConfig(spacer=SpacerConfig(lattice_contrast=0.0))
    sim = replace(sim, readout=replace(sim.readout, noise_counts=0.0, scan_jitter_ms=0.0))
    m = SkinModel(sim, SKIN, "hemisphere", np.random.default_rng(0))
    n = 80
    xyz = np.zeros((20 + n, 3))
    xyz[:, 2] = -2.0
    xyz[20:, 0], xyz[20:, 1] = 0.01 * np.arange(1, n + 1), 0.005 * np.arange(1, n + 1)
    rec = m.step_many(1e-3 * np.arange(20 + n), xyz, np.zeros(20 + n))[-1]
    fz, ft, u = rec[mk.S_FZ], rec[[mk.S_FX, mk.S_FY]], rec[[mk.S_UX, mk.S_UY]]
    assert rec[mk.S_SLIPPING] == 0.0 and np.hypot(*ft) > 0.1 and np.hypot(*u) > 0.1
    reference = ReferenceSkin(m)
    if not lean:
        from tests.sim.test_shear_mechanism import _without_the_lean

        _without_the_lean(reference)
    feet = rec[[mk.S_CX, mk.S_CY]]  # the cap's point in the sheet's frame, the columns' feet under it
    reach = pad_radius_mm("hemisphere", sim.spacer.width_mm) + 1.0
    step = 0.04
    g = np.arange(-reach, reach, step)
    x, y = np.meshgrid(g + feet[0], g + feet[1])
    contact, lattice, _ = reference.signed_fields(rec, x, y)
    area = step * step * 1e-3  # mm^2, kPa -> N
    assert contact.sum() * area == pytest.approx(fz, rel=0.01)
    assert lattice.sum() * area == pytest.approx(fz, rel=0.01)
    x_load = u + np.array([(contact * x).sum(), (contact * y).sum()]) / contact.sum()
    h = float(m.stack_height_mm(rec[mk.S_DELTA]))
    moment = np.array([(lattice * (x - feet[0])).sum(), (lattice * (y - feet[1])).sum()]) * area
    statics = fz * (x_load - feet) + ft * h
    if lean:
        np.testing.assert_allclose(moment, statics, rtol=0.03)
    else:
        assert np.all(moment < 0.85 * statics)


def test_shear_stiffness_rises_with_compression():
    ks = []
    for z in (-1.8, -2.1, -2.25):
        m = model()
        m.step(0.0, np.array([0.0, 0.0, z]))
        st = m.step(0.001, np.array([0.05, 0.0, z]))
        assert not st.slipping
        ks.append(st.force_n[0] / st.surface_shift_mm[0])
    assert ks[0] < ks[1] < ks[2]


def _slide_friction_bound_and_stick_slip_events(depth_mm: float):
    m = model()
    mu = m.sim.cover.friction
    states = [m.step(k * 1e-3, np.array([0.0, 0.0, -depth_mm])) for k in range(50)]
    for k in range(4000):  # 8 mm at 2 mm/s
        states.append(m.step(0.05 + k * 1e-3, np.array([0.002 * k, 0.0, -depth_mm])))
    ft = np.array([np.hypot(*s.force_n[:2]) for s in states])
    fz = np.array([s.force_n[2] for s in states])
    assert np.all(ft <= mu * fz + 1e-9)
    slipping = np.array([s.slipping for s in states])
    onsets = np.flatnonzero(slipping[1:] & ~slipping[:-1])
    assert len(onsets) >= 3  # stick-slip, not one steady slide
    assert ft.max() > 0.9 * mu * fz.max()
    slip = states[-1].slip_mm
    assert slip[0] < -1.0 and abs(slip[1]) < 1e-9  # the cover slid back relative to the indenter


@pytest.mark.xfail(strict=True, reason=(
    "measured with the stretching, wrinkling sheet and the cover's traction stiffness: pressed to 2.2 mm "
    "(2.88 N) the cap carries at most 0.67 of mu_s F_z over the 8 mm and never slips (0 onsets); pressed "
    "to 0.3 N it slips six times (the test below)"))
def test_slide_friction_bound_and_stick_slip_events():
    _slide_friction_bound_and_stick_slip_events(2.2)


@pytest.mark.xfail(strict=True, reason=(
    "measured with the stretching, wrinkling sheet: 1.2 mm is no longer a light press (0.72 N, not 0.3 N); "
    "the cap slips twice over the 8 mm (onsets at 4.7 and 6.5 mm of travel), not three times"))
def test_a_light_press_slides_within_the_friction_bound_in_stick_slip():
    """Pressed light enough (1.2 mm, about 0.3 N on the bending plate) that the cap slips within
    the 8 mm slide."""
    _slide_friction_bound_and_stick_slip_events(1.2)


def test_a_press_of_0_3_n_slides_within_the_friction_bound_in_stick_slip():
    """The same light press given by its load (0.3 N: 0.58 mm on the stretching sheet)."""
    from layerskin_exp.sim.physics_checks import _depth_for

    _slide_friction_bound_and_stick_slip_events(_depth_for(model(), 0.3))


def _without_couple_responses(m):
    """The skin model m with both routes' responses zeroed, the cover's couple tables and the
    lattice's at the pad's sides, which carry the lean too (the patterns then lie about the cap's
    line in the sheet's frame and nothing else)."""
    from dataclasses import replace

    t = m.tab
    m.tab = replace(t, cover_couple_kpa=0.0 * t.cover_couple_kpa, deep_couple_kpa=0.0 * t.deep_couple_kpa,
                    edge_deep_kpa=0.0 * t.edge_deep_kpa, edge_top_kpa=0.0 * t.edge_top_kpa)
    m._build_lookups()
    m._tables = m._kernel_tables()
    return m


def test_rod_torsion_friction_torque_bound_and_rotational_slip():
    """The rod pressed 2.3 mm and turned to 90 deg: the torque never exceeds the friction bound
    mu F_z |s|-mean, the contact slips in rotation (more than once: stick-slip), and while it
    sticks the torque loads the stack through the same two routes as a shear does. The cover's
    lever: a couple T H s / I_s per unit length along the line, which the couple response turns
    into a deep pressure odd across the line and growing along it (sign T s d). The lattice's:
    the in-plane-stiff sheet hands it a rotation field of traction, which ends at the pad's four
    sides as a pinwheel (across the sides x = +-L the couple per mm is -T h_L (2L - h) y / J,
    across y = +-L it is +T h_L (2L - h) x / J). The torque's part of the deep pressure (the
    state less the same state without its torque, the signed fields of the numpy reference) has
    those signs, and, a torque having no overturning moment, no net force or moment about the
    deep plane's axes. With the responses zeroed it is nothing. (Measured: first slip at 39 deg;
    while sticking the deep pattern's principal axis turns 0.0016 rad less than the superficial
    one's: the pinwheel has no net turn, and the cover's lever is a fifth of the stack.)"""
    from dataclasses import replace

    from layerskin_exp.sim import mechanics as mk
    from layerskin_exp.sim.reference import ReferenceSkin

    m = model("rod", k=20.0)
    states = [m.step(k * 1e-3, np.array([0.0, 0.0, -2.3])) for k in range(50)]
    for k in range(6000):
        yaw = math.radians(90.0) * min(k / 4000.0, 1.0)
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
    k_mid = next(k for k, s in enumerate(states[50:], 50) if not s.slipping and abs(s.surface_rotation_rad) > 0.1)
    torque = states[k_mid].torque_z_nmm
    assert torque > 1.0
    # the sticking state's pose on a fresh noise-free model (as the reference needs), with its torque and turn
    sim = replace(m.sim, readout=replace(m.sim.readout, noise_counts=0.0, scan_jitter_ms=0.0))
    fresh = SkinModel(sim, SKIN, "rod", np.random.default_rng(0), support_stiffness_n_per_mm=20.0)
    rec = fresh.step_many(np.array([0.0]), np.array([[0.0, 0.0, -2.3]]), np.array([states[k_mid].indenter_yaw_rad]))[0]
    rec[mk.S_TORQUE], rec[mk.S_THETA] = torque, states[k_mid].surface_rotation_rad
    untwisted = rec.copy()
    untwisted[mk.S_TORQUE] = 0.0

    def torques_part(zero, x, y):
        """The torque's part of the deep pressure on a noise-free model with the named tables zeroed."""
        skin = SkinModel(sim, SKIN, "rod", np.random.default_rng(0))
        skin.tab = replace(skin.tab, **{name: 0.0 * getattr(skin.tab, name) for name in zero})
        reference = ReferenceSkin(skin)
        return reference.signed_fields(rec, x, y)[1] - reference.signed_fields(untwisted, x, y)[1]

    couple_tables, edge_tables = ("cover_couple_kpa", "deep_couple_kpa"), ("edge_deep_kpa", "edge_top_kpa")
    # the lattice's route over the pad: a pinwheel at the sides, no net force or moment
    g = np.arange(-13.0, 13.0, 0.05) + 0.025
    x, y = np.meshgrid(g, g)
    lattice = torques_part(couple_tables, x, y)
    assert np.abs(lattice).max() > 0.1  # kPa
    assert abs(lattice.sum()) < 1e-3 * np.abs(lattice).sum()
    lever = (np.abs(lattice) * np.hypot(x, y)).sum()
    assert abs((lattice * x).sum()) < 1e-3 * lever and abs((lattice * y).sum()) < 1e-3 * lever
    # where the side load sits: within the bonded layer's end effect inside each side (the
    # default pad has no solid rim)
    assert m.sim.spacer.rim_width_mm == 0.0
    rim_from = half - edge_fade_mm(m.sim.spacer.thickness_mm)
    xs_side = (np.abs(x) > rim_from) & (np.abs(y) > 2.0) & (np.abs(y) < 8.0)
    ys_side = (np.abs(y) > rim_from) & (np.abs(x) > 2.0) & (np.abs(x) < 8.0)
    assert xs_side.any() and ys_side.any()
    assert np.all(np.sign(lattice[xs_side]) == -np.sign(torque * x * y)[xs_side])
    assert np.all(np.sign(lattice[ys_side]) == np.sign(torque * x * y)[ys_side])
    # the cover's lever, strip by strip along the line (s along it, d across it, about the cap's
    # line over the deep sheet, where the deep pattern lies, within the chord): no net force per
    # strip, a moment about the line of sign T s
    yaw_s = rec[mk.S_YAW]
    s_along, d_across = np.meshgrid(np.arange(-8.0, 8.01, 1.0), np.arange(-6.0, 6.0, 0.01) + 0.005)
    cover = torques_part(edge_tables, np.cos(yaw_s) * s_along - np.sin(yaw_s) * d_across,
                         np.sin(yaw_s) * s_along + np.cos(yaw_s) * d_across)
    assert np.abs(cover).max() > 0.1
    assert np.all(np.abs(cover.sum(axis=0)) < 1e-3 * np.abs(cover).sum(axis=0).max())
    moment = (cover * d_across).sum(axis=0)
    strips = np.abs(s_along[0]) >= 1.0
    assert np.all(np.sign(moment[strips]) == np.sign(torque * s_along[0][strips]))
    # the injection: both routes' responses zeroed, the torque loads nothing
    assert np.abs(torques_part(couple_tables + edge_tables, x, y)).max() == 0.0


def test_series_support_compliance():
    k = 5.0
    m = model(k=k)
    st = press(m, -3.0)
    assert st.indentation_mm + st.force_n[2] / k == pytest.approx(3.0, abs=1e-3)
    assert st.indentation_mm < 3.0
