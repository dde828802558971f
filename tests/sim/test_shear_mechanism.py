"""The shear's couple in the fast model comes from the stack's mechanics: the cover's lever acts
under the contact; the lattice's is handed over the pad by the in-plane-stiff sheet and ends at the
pad's edge, where the thin sheared layer puts half of it on the sheet and half straight on the deep
sheet; the couple's pressures balance its moment; the deep pattern lies about the cap's ground
position (the cap's point in the sheet's frame moved by the sheet's travel: the lattice carries the
load straight down), so the deep plane carries the load's moment where the sheared stack holds it.
The lattice's route lies at the pad's sides wherever the contact is."""

from dataclasses import replace

import numpy as np
import pytest
from scipy.optimize import fsolve

from layerskin_exp.sim import laminate
from layerskin_exp.sim.config import SimConfig
from layerskin_exp.sim.contact import _solver

SIM = SimConfig()
BENDING = replace(SIM, sheet=replace(SIM.sheet, large_deflection=False))  # the sheet as a bending plate only
RIMMED = replace(SIM, spacer=replace(SIM.spacer, rim_mm=None))  # the solid rim the lattice leaves (cast_rim)
EDGE_BAND_MM = 2.0  # the pad's outer band (the section's pad: 13 mm half-width; the lattice 2.5 mm high)


def _moment(plate, resp) -> float:
    return plate.first_moment(resp.foundation_kpa) - plate.first_moment(resp.contact_kpa)


@pytest.mark.parametrize("kind, depth", [("rod", 0.3), ("rod", 1.0), ("hemisphere", 0.8)])
@pytest.mark.parametrize("share", [0.0, 0.5, 0.9, 1.0])
def test_the_couple_balances_its_moment_whatever_the_levers(kind, depth, share):
    """The cover's route (its lever, 1 - s) and the lattice's (s, at the pad's edge) together
    carry the unit couple, at the loaded state and with the lattice's route as the fast model
    takes it (a straight side of the unloaded lattice)."""
    plate = _solver(SIM, kind)
    sol = plate.solve(depth)
    cover = _moment(plate, plate.couple(sol, share))
    assert cover + share * _moment(plate, plate.edge_couple(sol)) == pytest.approx(1.0, abs=1e-2)
    side = _solver(SIM, "rod")
    assert cover + share * _moment(side, side.edge_couple()) == pytest.approx(1.0, abs=1e-2)


def test_without_the_walls_shear_the_lattices_part_loses_its_balance(monkeypatch):
    """The lattice's reaction near the pad's edge is partly its walls' shear (the operator's
    Pasternak part): left out, the couple handed to the lattice no longer balances."""
    plate = _solver(SIM, "rod")
    sol = plate.solve(0.5)
    for state in (sol, None):
        assert _moment(plate, plate.edge_couple(state)) == pytest.approx(1.0, abs=1e-2)
    monkeypatch.setattr(laminate.PlateOnFoundation, "_lattice_m1", lambda self, w1, slope: slope * w1)
    for state in (sol, None):
        assert _moment(plate, plate.edge_couple(state)) != pytest.approx(1.0, abs=1e-2)


@pytest.mark.parametrize("depth", [0.3, 0.6, 1.0])
def test_the_lattices_part_lies_at_the_pads_edge_and_the_covers_under_the_contact(depth):
    plate = _solver(SIM, "rod")
    sol = plate.solve(depth)
    x = plate.x
    edge = np.abs(x) >= plate.pad_radius - EDGE_BAND_MM
    near = np.abs(x) <= 4.0

    def share_of_moment(resp, where):
        return plate.first_moment(np.where(where, resp.foundation_kpa, 0.0)) / plate.first_moment(resp.foundation_kpa)

    lattice, cover = plate.edge_couple(sol), plate.couple(sol, 0.0)
    assert share_of_moment(lattice, edge) > 0.5
    assert abs(share_of_moment(lattice, near)) < 0.05
    # the cover's part stays near the contact: a couple placed there would fail the first check
    assert share_of_moment(cover, edge) < 0.1
    assert share_of_moment(cover, near) > 0.3


def _strip_end_root(nu: float) -> complex:
    """The slowest end effect of an elastic strip bonded on both faces (plane strain): the root
    w = lambda h of (3 - 4 nu) sin w + w = 0 near Re w = 4.3 (the first root off the real axis)."""
    kappa = 3.0 - 4.0 * nu

    def residual(v):
        r = kappa * np.sin(complex(v[0], v[1])) + complex(v[0], v[1])
        return [r.real, r.imag]

    w = complex(*fsolve(residual, [4.3, 1.5], xtol=1e-12))
    assert abs(kappa * np.sin(w) + w) < 1e-9
    return w


@pytest.mark.parametrize("nu", [0.0, 0.3, 0.5])
def test_the_end_decay_is_the_bonded_strips_slowest_root(nu):
    """END_DECAY is the incompressible strip's root, the lowest (the farthest-reaching end effect)
    of the range the homogenised lattice's Poisson's ratio can take."""
    w = _strip_end_root(nu)
    assert laminate.END_DECAY <= w.real + 1e-3
    if nu == 0.5:
        assert laminate.END_DECAY == pytest.approx(w.real, abs=5e-3)


def _direct_centre_inside_mm(plate, resp) -> float:
    """How far inside the pad's side (mm) the lattice's direct part acts: the signed centroid
    of its moment on the x > 0 side (negative: beyond the side, where a couple outweighs the net load)."""
    half = (plate.x > 0) & plate.on_pad
    d = resp.direct_kpa[half]
    return float(((plate.pad_radius - plate.x[half]) * d).sum() / d.sum())


def _rimless(plate):
    """The same plate with its lattice out to the pad's side (no solid rim)."""
    return laminate.PlateOnFoundation(plate.kind, plate.law, plate.rigidity, plate.pasternak, plate.k_cover,
                                      plate.radius, plate.pad_radius, plate.step, plate.interface,
                                      plate.cover_shear_n_per_mm3, rim_mm=0.0)


def _rim_inset_closed_form(cfg, fade: float) -> float:
    """The side load's centroid inside the side, from h tau' with the rim (width b, shear
    modulus r times the lattice's): r exp(-s / l) / l on 0 < s < b, less the step
    r (1 - exp(-b / l)) - 1 at s = b. Net 1; moment about the side
    r l (1 - exp(-b / l)) - b (r - 1)."""
    b, r = cfg.rim_width_mm, cfg.solid_shear_modulus_kpa / cfg.shear_modulus_kpa
    return r * fade * (1.0 - np.exp(-b / fade)) - b * (r - 1.0)


def _grid_tolerance(plate, cfg, fade: float) -> float:
    """The closed form's step sits at s = b; the grid puts it on its first lattice point, up to
    one step away, moving the centroid by up to (its weight + the net 1) x step."""
    r = cfg.solid_shear_modulus_kpa / cfg.shear_modulus_kpa
    return (r * (1.0 - np.exp(-cfg.rim_width_mm / fade)) - 1.0 + 1.0) * plate.step


@pytest.mark.parametrize("kind", ["rod", "hemisphere"])
def test_the_lattice_hands_half_its_moment_straight_to_the_deep_sheet(kind):
    """A thin layer in shear: its normal stress changes by h dtau/dx from top to base, and its
    compression follows the mean, so half of its moment's edge term bypasses the sheet. The
    direct part carries half the lattice's moment at the pad's side, where the traction fades as
    the bonded layer's end effect over h / Re(w) (w the strip's root, `_strip_end_root`,
    nu = 0.5). In the pad's solid rim the traction is the solid's, 2 / rho times the lattice's,
    so the direct part acts where the closed form of that traction puts it (beyond the side:
    the rim's couple outweighs its net load); without the rim, h / Re(w) inside the side. The
    sheet-borne rest still balances the other half with the cap's share."""
    cfg = RIMMED.spacer
    assert cfg.rim_width_mm > 0
    plate = _solver(RIMMED, kind)
    fade = plate.law.h_mm / _strip_end_root(0.5).real
    for case, want, tol in ((plate, _rim_inset_closed_form(cfg, fade), _grid_tolerance(plate, cfg, fade)),
                            (_rimless(plate), fade, 0.1 * fade)):
        for resp in (case.edge_couple(case.solve(0.6)), case.edge_couple()):
            assert case.first_moment(resp.direct_kpa) == pytest.approx(0.5, rel=1e-6)
            assert _direct_centre_inside_mm(case, resp) == pytest.approx(want, abs=tol)
            sheet_borne = case.first_moment(resp.foundation_kpa - resp.direct_kpa) - case.first_moment(resp.contact_kpa)
            assert sheet_borne == pytest.approx(0.5, abs=1e-2)
        assert case.side_inset_mm() == pytest.approx(want, abs=tol)


def test_a_missing_rim_or_an_end_effect_as_deep_as_the_lattice_is_caught(monkeypatch):
    """Injections: the lattice run out to the side (no rim) is far from the rim's closed form;
    and without a rim, the traction fading over the lattice's whole height (the band the fast
    model used before) puts the direct part about h inside the side. The checks above refuse both."""
    cfg, plate = RIMMED.spacer, _solver(RIMMED, "rod")
    fade = plate.law.h_mm / _strip_end_root(0.5).real
    bare = _rimless(plate)
    centre = _direct_centre_inside_mm(bare, bare.edge_couple())
    assert abs(centre - _rim_inset_closed_form(cfg, fade)) > 5.0 * _grid_tolerance(plate, cfg, fade)
    monkeypatch.setattr(laminate, "END_DECAY", 1.0)
    centre = _direct_centre_inside_mm(bare, bare.edge_couple())
    assert centre != pytest.approx(fade, rel=0.1)
    assert centre > 2.0 * fade


def test_the_couple_refuses_a_share_outside_0_1():
    plate = _solver(SIM, "rod")
    sol = plate.solve(0.5)
    with pytest.raises(ValueError, match="lattice_share=1.2"):
        plate.couple(sol, 1.2)


@pytest.mark.parametrize("kind,sim", [
    ("rod", SIM), ("hemisphere", BENDING),
    pytest.param("hemisphere", SIM, marks=pytest.mark.xfail(strict=True, reason=(
        "the stretching sheet's deep pressure map moves its CoP 0.93 mm for 1 mm of drag (the bending "
        "plate's: 1.00 within 0.05): its field, spread by the membrane, reaches the pad's sides, where "
        "the fold and the array's edge take part of the move (not separated further)")))])
def test_the_deep_pattern_follows_the_sheets_travel_and_the_superficial_one_stays(kind, sim):
    """The sheet dragged 1 mm along x (no shear force, no torque): the superficial taxels ride on
    the sheet, so the superficial map is that of the undragged sheet (its CoP moves by less than
    0.02 mm); the lattice carries the load straight down from where the sheet point under the cap
    now is, so the deep map's CoP moves with the drag, by 1 mm within 0.05 mm. With no shear or torque nothing takes the lattice's route. (The deep pattern left at
    the columns' feet is refused by the statics below, where it misses F_z u.)"""
    from layerskin_exp import rig
    from layerskin_exp.config import SkinConfig
    from layerskin_exp.sim import mechanics as mk
    from layerskin_exp.sim.skin import SkinModel

    radius = rig.INDENTER_RADIUS_MM if kind == "rod" else None
    model = SkinModel(sim, SkinConfig(), kind, np.random.default_rng(0), contact_radius_mm=radius)
    depth = 0.6 if kind == "rod" else 1.0
    rec = model.step_many(np.array([0.0]), np.array([[0.4, 0.3, -depth]]), np.array([np.pi / 2]))[0]
    assert rec[mk.S_FZ] > 0 and rec[mk.S_FX] == 0.0
    centres = model.skin.taxel_centres_mm()

    def cop_moves(drag_mm):
        dragged = rec.copy()
        dragged[mk.S_UX] += drag_mm
        dragged[mk.S_SERIAL] = rec[mk.S_SERIAL] + 1000  # another configuration: no map reused
        still, moved = (np.stack(model.pressure_maps([model.state_of(r)]))[:, 0] for r in (rec, dragged))
        x = np.broadcast_to(centres[None, :], still[0].shape)
        out = []
        for layer in range(2):
            assert still[layer].max() > 0
            a, b = still[layer], moved[layer]
            out.append((b * x).sum() / b.sum() - (a * x).sum() / a.sum())
        return out

    sup, deep = cop_moves(1.0)
    assert abs(sup) < 0.02
    assert deep == pytest.approx(1.0, abs=0.05)


@pytest.mark.parametrize("kind", ["rod", "hemisphere"])
def test_the_superficial_core_reads_the_mean_of_the_contact_and_the_lattice(kind):
    """The superficial FSR's core lies between the sheet's films: it reads half the load on the
    sheet's top (the contact) and half the lattice's reaction on its bottom, so its profile carries
    the whole load, as the deep layer's does (each equals the row's load by the laminate's own
    equilibrium). Reading either side alone, or both in full, breaks the balance by a factor."""
    from layerskin_exp import rig
    from layerskin_exp.config import SkinConfig
    from layerskin_exp.sim.skin import SkinModel

    radius = rig.INDENTER_RADIUS_MM if kind == "rod" else None
    tab = SkinModel(SIM, SkinConfig(), kind, np.random.default_rng(0), contact_radius_mm=radius).tab
    d = tab.dist_mm
    weight = np.gradient(d) if kind == "rod" else 2.0 * np.pi * d * np.gradient(d)  # mm or mm^2 per sample
    rows = [k for k in (10, 40, 80) if tab.load[k] > 0]
    assert len(rows) == 3
    for k in rows:
        assert tab.superficial_kpa[k] @ weight * 1e-3 == pytest.approx(tab.load[k], rel=1e-2)
        assert tab.deep_kpa[k] @ weight * 1e-3 == pytest.approx(tab.load[k], rel=1e-2)
        # where the cover's spread of the contact has died out (beyond the contact by five cover
        # thicknesses) the superficial core reads half the lattice's pressure (blurred alike)
        outside = np.abs(d) > tab.contact_halfwidth_mm[k] + 5.0 * SIM.cover.thickness_mm
        lattice_there = tab.deep_kpa[k][outside] @ weight[outside]
        assert lattice_there > 0.05 * (tab.deep_kpa[k] @ weight)  # a part worth checking
        assert tab.superficial_kpa[k][outside] @ weight[outside] == pytest.approx(0.5 * lattice_there, rel=1e-2)


@pytest.mark.parametrize("lean", [True, False])
@pytest.mark.parametrize("delta_mm", [0.5, 1.0, 1.5])
def test_the_deep_plane_carries_the_moment_of_the_load_where_the_sheared_stack_holds_it(delta_mm, lean, request):
    """Statics of the stack as it stands when sheared: the lattice's pressure on the deep plane
    balances the contact's load where that load now sits and the shear at the cover's top,
    int p_lattice (x - x_feet) = F_z (x_load - x_feet) + F_t H (per unit length of a rod across
    the pad; x_feet the feet of the columns under the contact; the load stands the sheet's
    travel ahead of them, and the deep pattern lies under the load). The
    reference section meets this on its deep line (its pressure's first moment is F_z x_load +
    F_x H within 3 %, load_x_mm and load_height_mm of its states). Here the fast model's signed
    fields (the numpy reference of the kernels), stuck at F_t / F_z = 1/3, at three presses.
    Without the sheet's travel in the deep pattern's position (the pattern left at the columns'
    feet, the moment F_z u with no route) the deep plane misses F_z u."""
    from layerskin_exp import rig
    from layerskin_exp.config import SkinConfig
    from layerskin_exp.sim import mechanics as mk
    from layerskin_exp.sim.reference import ReferenceSkin
    from layerskin_exp.sim.skin import SkinModel

    if lean and delta_mm == 1.5:
        request.node.add_marker(pytest.mark.xfail(strict=True, reason=(
            "measured with the cover's traction stiffness: moment 0.0830 against the statics' 0.0803 N mm/mm "
            "(+3.4 %, band 3 %); the line x in [-13.5, 13.5] mm stops short of the sides' route, which "
            "reaches 14 mm: on [-16, 16] it holds within 3 % (the cap now travels further over the sheet)")))
    sim = replace(SIM, readout=replace(SIM.readout, noise_counts=0.0, scan_jitter_ms=0.0))  # as ReferenceSkin needs
    model = SkinModel(sim, SkinConfig(), "rod", np.random.default_rng(0), contact_radius_mm=rig.INDENTER_RADIUS_MM)
    xs = np.linspace(0.0, 3.0, 601)[1:]
    recs = model.step_many(1e-3 * np.arange(len(xs) + 1),
                           np.column_stack([np.r_[0.0, xs], np.zeros(len(xs) + 1), np.full(len(xs) + 1, -delta_mm)]),
                           np.full(len(xs) + 1, np.pi / 2))[1:]
    k = int(np.argmax(recs[:, mk.S_FX] >= recs[:, mk.S_FZ] / 3.0))
    rec = recs[k]
    assert k > 0 and rec[mk.S_SLIPPING] == 0.0 and rec[mk.S_UX] > 0.05  # stuck, and the sheet travelled
    x = np.arange(-13.5, 13.5, 0.005)  # across the rod (along y), mid-chord
    reference = ReferenceSkin(model)
    if not lean:
        _without_the_lean(reference)
    contact, lattice, _ = reference.signed_fields(rec, x, np.zeros_like(x))
    s1, s2 = mk.chord(rec[mk.S_CX], rec[mk.S_CY], rec[mk.S_YAW], model._half)
    fz, fx = rec[mk.S_FZ] / (s2 - s1), rec[mk.S_FX] / (s2 - s1)  # N per mm of rod
    dx = x[1] - x[0]
    assert contact.sum() * dx * 1e-3 == pytest.approx(fz, rel=0.02)
    assert lattice.sum() * dx * 1e-3 == pytest.approx(fz, rel=0.02)
    feet = rec[mk.S_CX]  # the contact in the sheet's frame: the columns' feet under it, on the deep plane
    x_load = rec[mk.S_UX] + (contact @ x) / contact.sum()  # where the contact's load now sits
    h = float(model.stack_height_mm(rec[mk.S_DELTA]))
    moment = (lattice @ (x - feet)) * dx * 1e-3
    statics = fz * (x_load - feet) + fx * h
    if lean:
        assert moment == pytest.approx(statics, rel=0.03)
    else:
        assert moment < 0.85 * statics


def _without_the_lean(reference) -> None:
    """The injection of the statics checks: the deep pattern left at the columns' feet (the
    sheet's travel and turn taken as zero for the lattice's fields only; the contact's stay in the
    sheet's frame, where they are)."""
    from layerskin_exp.sim import mechanics as mk

    signed_fields = reference.signed_fields

    def at_the_feet(rec, x, y, cells=1.0):
        contact, _, top = signed_fields(rec, x, y, cells)
        still = rec.copy()
        still[[mk.S_UX, mk.S_UY, mk.S_THETA]] = 0.0
        return contact, signed_fields(still, x, y, cells)[1], top

    reference.signed_fields = at_the_feet


def test_the_lattices_route_lies_at_the_pads_sides_wherever_the_contact_is(monkeypatch):
    """The lattice's part of the couple is handed over the whole pad by the in-plane-stiff sheet,
    so its pressure lies at the pad's sides and does not move with the contact (the 3D model's
    lattice carries 5 % of its shear traction within 3 mm of the cap, 18 % within 6 mm): the same sheared state at the centre and 8 mm off it gives the same route (deep and
    top), near the sides (inside the pad, more than 8 mm from every side, below 5 % of its peak).
    Placed about the contact instead, as before e3c57ee (the injection: the route's coordinates
    taken from the contact), the two differ and the off-centre one reaches into the grid."""
    from layerskin_exp.config import SkinConfig
    from layerskin_exp.sim import mechanics as mk
    from layerskin_exp.sim.reference import ReferenceSkin
    from layerskin_exp.sim.skin import SkinModel

    sim = replace(SIM, readout=replace(SIM.readout, noise_counts=0.0, scan_jitter_ms=0.0))
    model = SkinModel(sim, SkinConfig(), "hemisphere", np.random.default_rng(0))
    rec = model.step_many(np.array([0.0]), np.array([[0.0, 0.0, -2.0]]), np.zeros(1))[0]
    rec[[mk.S_FX, mk.S_FY, mk.S_UX, mk.S_UY]] = (-1.0, 0.4, -0.3, 0.1)
    off = rec.copy()
    off[mk.S_CX] = 8.0
    g = np.arange(-13.0, 13.0, 0.1) + 0.05
    x, y = np.meshgrid(g, g)

    def routes(reference):
        return [np.stack(reference.edge_fields(r, x, y, 2.0)) for r in (rec, off)]

    centred, moved = routes(ReferenceSkin(model))
    peak = np.abs(centred).max()
    assert peak > 0.5  # kPa
    np.testing.assert_allclose(moved, centred, atol=1e-9 * peak)
    inside = (np.abs(x) < 5.0) & (np.abs(y) < 5.0)
    assert np.abs(centred[:, inside]).max() < 0.05 * peak

    # the injection: the route placed about the contact
    reference = ReferenceSkin(model)
    edge_fields = reference.edge_fields

    def about_the_contact(r, x, y, h_lat):
        return edge_fields(r, x - r[mk.S_CX], y - r[mk.S_CY], h_lat)

    monkeypatch.setattr(reference, "edge_fields", about_the_contact)
    centred, moved = routes(reference)
    assert not np.allclose(moved, centred, atol=1e-9 * peak)
    assert np.abs(moved[:, inside]).max() > 0.05 * peak


def test_the_rim_is_a_design_parameter_that_reaches_the_plate_and_the_reference_it_is_judged_by():
    """`sim.spacer.rim_mm`: 0 (the default) a lattice out to the pad's sides, as the study
    describes it and the 3D model is built; null what the lattice leaves beyond its last full wall
    (the reference's section); the plate carries the width it is given, the section's diagnostics
    judge a rimless pad against the rimless homogenised section, and a width outside the half-pad
    is refused naming the key."""
    from layerskin_exp.config import ConfigError
    from layerskin_exp.sim.fem_reference.alignment import homogenised_for
    from layerskin_exp.sim.spacer_config import SpacerConfig

    assert SIM.spacer.rim_mm == 0.0 and SIM.spacer.rim_width_mm == 0.0
    assert SIM.spacer.lattice_rim_mm == pytest.approx(0.778, abs=1e-3)
    for rim, name in ((0.0, "homogenised_no_rim"), (1.5, "homogenised"), (None, "homogenised")):
        sim = replace(SIM, spacer=replace(SIM.spacer, rim_mm=rim))
        plate = _solver(sim, "rod")
        want = SIM.spacer.lattice_rim_mm if rim is None else rim
        assert plate.rim_mm == want
        assert plate.rim.any() == (want > 0)
        assert homogenised_for(sim) == name
    with pytest.raises(ConfigError, match=r"sim\.spacer\.rim_mm=13"):
        SpacerConfig(rim_mm=13.0)
