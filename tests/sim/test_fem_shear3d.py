"""The 3D half-model of the hemisphere's press and shear (layerskin_exp.sim.fem_reference.shear3d):
its homogenised lattice against the honeycomb's closed forms (Gibson & Ashby 1997, sec. 4.4:
E3 = rho E_s, G13 = rho G_s / 2; the same 5 % and 15 % as tests/sim/test_fem_closed_forms.py),
and the committed 3D data's balance: every layer's 2 sum(p A) equals F_z within 2 %, a check
that fails on an injected extraction error."""

from __future__ import annotations

import numpy as np
import pytest

from layerskin_exp.sim.config import SimConfig
from layerskin_exp.sim.fem_reference import model as fe_model
from layerskin_exp.sim.fem_reference import shear3d as s3
from layerskin_exp.sim.fem_reference.model import KPA, Section
from layerskin_exp.sim.laminate import sheet_rigidity_n_mm

SEC = Section.from_sim(SimConfig())


def _stress_kpa(F: np.ndarray) -> np.ndarray:
    """The homogenised lattice's first Piola stress (kPa) at one deformation gradient."""
    umat = s3.lattice_material(SEC)
    P = umat.gradient([F.reshape(3, 3, 1, 1), None])[0]
    return P[..., 0, 0] / KPA


def lattice_moduli3d(strain: float = 0.01) -> tuple[float, float]:
    """(E3, G13) in kPa: uniaxial stress along z (laterally free) and simple shear in xz."""
    F = np.eye(3)
    F[2, 2] = 1.0 - strain
    e3 = -_stress_kpa(F)[2, 2] / strain
    F = np.eye(3)
    F[0, 2] = strain
    g13 = _stress_kpa(F)[0, 2] / strain
    return float(e3), float(g13)


def test_the_homogenised_lattice_meets_the_honeycombs_moduli():
    e3, g13 = lattice_moduli3d()
    e_hc, g_hc = SEC.honeycomb_moduli_kpa()
    assert e3 == pytest.approx(e_hc, rel=0.05), (e3, e_hc)
    assert g13 == pytest.approx(g_hc, rel=0.15), (g13, g_hc)


def test_the_moduli_check_sees_a_missing_through_thickness_term(monkeypatch):
    """Without its through-thickness term the layer is the matrix alone (E = 2 G13): the check must fail."""
    monkeypatch.setattr(fe_model, "lattice_constants", lambda sec: {"mu": sec.honeycomb_moduli_kpa()[1] * KPA,
                                                             "bulk": 0.0, "k": 0.0})
    e3, _ = lattice_moduli3d()
    assert e3 != pytest.approx(SEC.honeycomb_moduli_kpa()[0], rel=0.05)


def _fibre(k: float, axis: int):
    """The lattice term this model had before: W = k / 8 (C_aa - 1)^2 on the material fibre along
    the axis (a counter-example for the checks below)."""
    def stress(x, k):
        F, sv = x[0], x[-1]
        c = np.einsum("a...,a...->...", F[:, axis], F[:, axis])
        P = np.zeros_like(F)
        P[:, axis] = 0.5 * k * (c - 1.0) * F[:, axis]
        return [P, sv]

    def elasticity(x, k):
        F = x[0]
        c = np.einsum("a...,a...->...", F[:, axis], F[:, axis])
        A = np.zeros((3, 3, 3, 3, *F.shape[2:]))
        A[:, axis, :, axis] = k * np.einsum("i...,k...->ik...", F[:, axis], F[:, axis])
        for i in range(3):
            A[i, axis, i, axis] += 0.5 * k * (c - 1.0)
        return [A]

    return fe_model.fem.Material(stress, elasticity, k=k)


@pytest.mark.parametrize("axis", [1, 2])
def test_the_plane_separation_terms_derivatives_are_its_energys(axis):
    """P = dW/dF and A = dP/dF of `plane_separation` against central differences of
    W = k / 8 (1 / (C^-1)_aa - 1)^2 at a random deformation."""
    k = 1.3
    umat = fe_model.plane_separation(k, axis)
    F = (np.eye(3) + 0.3 * np.random.default_rng(axis).standard_normal((3, 3)))[:, :, None, None]

    def energy(F):
        g = np.linalg.inv(F[:, :, 0, 0])[axis]
        return k / 8 * (1.0 / (g @ g) - 1.0) ** 2

    P, A = umat.gradient([F, None])[0][..., 0, 0], umat.hessian([F, None])[0][..., 0, 0]
    eps = 1e-6
    for m in range(3):
        for n in range(3):
            d = np.zeros((3, 3, 1, 1))
            d[m, n] = eps
            assert P[m, n] == pytest.approx((energy(F + d) - energy(F - d)) / (2 * eps), abs=1e-8)
            dP = (umat.gradient([F + d, None])[0] - umat.gradient([F - d, None])[0])[..., 0, 0] / (2 * eps)
            np.testing.assert_allclose(A[:, :, m, n], dP, atol=1e-8)


def transverse_shear_tangent_kpa(umat, stretch: float) -> float:
    """dP_xz / dF_xz (kPa) after compressing along z to `stretch`: the layer's resistance to a
    transverse shear under that preload."""
    F = np.diag([1.0, 1.0, stretch])[:, :, None, None]
    return float(umat.hessian([F, None])[0][0, 2, 0, 2, 0, 0] / KPA)


@pytest.mark.parametrize("stretch", [0.9, 0.5, 0.3])
def test_the_compressed_lattice_still_resists_transverse_shear(stretch):
    """Pressed to the study's 3 N the lattice reaches C33 ~ 0.1 (stretch 0.3): its transverse shear
    tangent must stay positive there (it is the matrix's G13), or no sticking shear converges."""
    g = SEC.honeycomb_moduli_kpa()[1]
    assert transverse_shear_tangent_kpa(s3.lattice_material(SEC), stretch) == pytest.approx(g, rel=1e-6)


def test_the_shear_tangent_check_sees_the_fibres_instability():
    """The fibre term the lattice had (W on C33): its shear tangent mu + k (C33 - 1) / 2 turns
    negative below C33 = 0.495, and the check above sees it."""
    c = fe_model.lattice_constants(SEC)
    fibre = fe_model.fem.CompositeMaterial(fe_model.fem.NeoHookeCompressible(mu=c["mu"], lmbda=0.0), _fibre(c["k"], 2))
    assert transverse_shear_tangent_kpa(fibre, 0.9) > 0
    assert transverse_shear_tangent_kpa(fibre, 0.5) < 0
    # the same uniaxial modulus, so the moduli tests cannot tell the two apart
    assert _fibre(c["k"], 2).hessian([np.diag([1, 1, 0.99])[:, :, None, None], None])[0][2, 2, 2, 2, 0, 0] == pytest.approx(
        fe_model.plane_separation(c["k"], 2).hessian([np.diag([1, 1, 0.99])[:, :, None, None], None])[0][2, 2, 2, 2, 0, 0])


def test_the_merged_sheet_bends_like_the_laminate():
    """One layer of the sheet's thickness with E = merged_sheet_e_mpa has the crossed laminate's D:
    the fast model's closed form for the bonded sheet (laminate.sheet_rigidity_n_mm: the two faces'
    membrane stiffnesses in series times the films' separation squared, plus each layer's own
    bending) within 7 % (that form hinges the across-strip film's copper, this integral does not),
    and the exact integral of E (z - z_n)^2 over the three layers."""
    e = s3.merged_sheet_e_mpa(SEC)
    t = 2 * SEC.film_mm + SEC.core_mm
    nu = 0.34
    sh = SimConfig().sheet
    closed = sheet_rigidity_n_mm(sh.film_modulus_mpa, sh.film_thickness_mm, sh.copper_modulus_mpa,
                                 sh.copper_thickness_mm, sh.electrode_fill, sh.velostat_thickness_mm,
                                 sh.velostat_modulus_mpa, bonded=True, poisson=nu)
    assert e * t ** 3 / (12 * (1 - nu ** 2)) == pytest.approx(closed, rel=0.07)
    z = np.linspace(0.0, t, 200001)
    ez = np.where(z < SEC.film_mm, SEC.film_across_e_mpa, np.where(z > t - SEC.film_mm, SEC.film_along_e_mpa,
                                                                     SEC.core_e_mpa))
    neutral = float(np.sum(ez * z) / np.sum(ez))
    d_lam = float(np.sum(ez * (z - neutral) ** 2) * (z[1] - z[0]))
    assert e * t ** 3 / 12 == pytest.approx(d_lam, rel=1e-3)


def _tilted(theta):
    """A rigid rotation about y by theta (the half-model's symmetry keeps y = 0 a plane)."""
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def test_a_planes_normals_are_its_deformed_tangents_cross_product():
    """Exact for a rigid tilt and for a bowl curved in x and in y (the y = 0 edge needs the mirror)."""
    fe = s3.Stack3D(SEC, x_edges=s3.X_EDGES_MM, y_edges=s3.Y_EDGES_MM)
    nodes, _ = fe.plane(fe.line_z()["superficial"])
    p = fe.points
    rot = _tilted(0.05)
    fe.u[:] = p @ rot.T - p
    assert np.abs(fe.plane_normals(nodes) - rot[:, 2]).max() < 1e-12
    fe.u[:] = 0.0
    fe.u[:, 2] = -(0.02 * p[:, 0] ** 2 + 0.03 * p[:, 1] ** 2)
    x, y = p[nodes, 0], p[nodes, 1]
    bowl = np.stack([0.04 * x, 0.06 * y, np.ones_like(x)], axis=1)
    bowl /= np.linalg.norm(bowl, axis=1, keepdims=True)
    assert np.abs(fe.plane_normals(nodes) - bowl).max() < 1e-9


@pytest.mark.parametrize("plane", ["superficial", "sheet_top", "deep"])
def test_a_tilted_sheet_reads_along_its_normal_what_it_read_flat(plane):
    """An FSR reads the pressure normal to itself, so a rigidly tilted stack reads what it read
    flat: the traction along the plane's normal keeps its value (the material law is objective),
    while its z component takes up the tilt (4 kPa of 776 at 0.1 rad in the compressed sheet)."""
    fe = s3.Stack3D(SEC, x_edges=s3.X_EDGES_MM, y_edges=s3.Y_EDGES_MM)
    z = fe.line_z()[plane]
    p = fe.points
    fe.u[:] = 0.0
    fe.u[:, 2] = -0.05 * p[:, 2]  # a uniform compression of the whole stack
    _, w, g = fe.transmitted(z)
    flat = g[:, 2] / w
    rot = _tilted(0.1)
    fe.u[:] = (p + fe.u) @ rot.T - p
    nodes, w, g = fe.transmitted(z)
    normal = (g * fe.plane_normals(nodes)).sum(axis=1) / w
    assert np.abs(normal - flat).max() < 1e-8 * np.abs(flat).max()
    if plane != "sheet_top":  # (the cover's face carries next to nothing at this strain)
        assert np.abs(g[:, 2] / w - flat).max() > 1e-3 * np.abs(flat).max()


@pytest.fixture(scope="module")
def committed():
    path = s3.DATA / "shear3d.npz"
    with np.load(path) as z:
        return {k: z[k] for k in z.files}


def test_every_layer_of_the_3d_data_carries_the_load(committed):
    bal = s3.balance3d(committed)
    assert set(bal) == {"superficial", "deep", "interface", "base", "sheet_top", "sheet_bottom", "contact"}
    assert len(committed["phase"]) >= 2
    for line, b in bal.items():
        assert np.all(np.abs(b - 1.0) < s3.BALANCE_TOL), (line, b)


def test_every_plane_of_the_3d_data_carries_the_loads_moment(committed):
    moments = s3.moment_balance3d(committed)
    assert moments is not None and set(moments) == {"superficial", "deep", "interface", "base", "sheet_top", "sheet_bottom"}
    for line, err in moments.items():
        assert np.all(np.abs(err) < s3.MOMENT_TOL), (line, err)


def test_the_3d_balance_sees_an_extraction_error(committed):
    """Areas from the corner nodes' spacing alone (a bilinear lumping, mid-side nodes given the
    same share as corners) break the balance of the deep layer's map."""
    bad = dict(committed)
    w = np.asarray(committed["deep_w_mm2"], float)
    bad["deep_w_mm2"] = np.full_like(w, w.sum() / len(w))
    with pytest.raises(RuntimeError, match="does not carry the load"):
        s3.require_balance3d(bad, log=lambda *_: None)


def _pressed_and_sheared() -> list[dict]:
    """A coarse half-model pressed 0.3 mm and sheared sticking by 0.3 mm: its two states."""
    fe = s3.Stack3D(SEC, x_edges=(-13.0, -1.0, 0.0, 1.0, 2.0, 13.0), y_edges=(0.0, 1.0, 13.0))
    top = fe.height_mm + SEC.radius_mm
    fe.move_to(np.array([0.0, 0.0, top - 0.3]), sticking=False, step_mm=0.1)
    states = [fe.state()]
    fe.stick_all_in_contact()
    fe.move_to(np.array([0.3, 0.0, fe.centre[2]]), sticking=True, step_mm=0.1)
    states.append(fe.state())
    return states


def _moments(states: list[dict]) -> dict:
    return s3.moment_balance3d(s3.scalars(states))


def test_every_plane_of_the_3d_model_carries_the_loads_moment():
    """Statics of everything above each layer's plane, the nodes where they are now: the first
    moment of the normal force through it is the load's plus that of the tangential force through
    it, in the press and in the shear; and the sheared load acts ahead of the cap (its flank)."""
    states = _pressed_and_sheared()
    assert states[1]["fx_n"] > 0.02
    for line, err in _moments(states).items():
        assert np.all(np.abs(err) < s3.MOMENT_TOL), (line, err)
    s3.require_moment_balance3d(s3.scalars(states), log=lambda *_: None)
    # the deep plane's force CoP meets x_load + F_x h / F_z without the cap's centre in it
    sheared = states[1]
    assert sheared["deep_cop_world_mm"] > sheared["load_x_mm"] > sheared["cap_x_mm"]


def test_the_3d_moment_balance_sees_forces_put_on_the_wrong_nodes(monkeypatch):
    """The plane's forces paired with its nodes in reverse order (every layer still carries F_z,
    so the force balance passes) break the moment balance of the sheared state."""
    real = s3.Stack3D.transmitted

    def reversed_nodes(self, z_mm):
        nodes, w, g = real(self, z_mm)
        return nodes, w, g[::-1]

    monkeypatch.setattr(s3.Stack3D, "transmitted", reversed_nodes)
    states = _pressed_and_sheared()
    worst = max(float(np.abs(e).max()) for e in _moments(states).values())
    assert worst > s3.MOMENT_TOL
    with pytest.raises(RuntimeError, match="does not carry the load's moment"):
        s3.require_moment_balance3d(s3.scalars(states), log=lambda *_: None)


def test_the_3d_data_was_sheared():
    """Each branch the committed 3D data starts is sheared along +x with F_x along the travel."""
    with np.load(s3.DATA / "shear3d.npz") as z:
        phase, fx, x = z["phase"], z["fx_n"], z["cap_x_mm"]
    sheared = phase == 1
    assert sheared.any()
    assert np.all(fx[sheared] > 0) and np.all(x[sheared] > 0)


def test_the_taxel_map_puts_each_layers_load_on_the_taxels(committed, monkeypatch):
    """With electrodes as wide as the pitch on a grid that covers the pad, the 3D half-model's
    press maps, read with their mirror half, put the map's compressive load (twice the half's
    sum of p+ A; the reader reads tension as none) on the taxels: the reader's areas are the
    nodes' and the mirror is counted once. Without the mirror the same sum is half of it."""
    from layerskin_exp import rig
    from layerskin_exp.sim.fem_reference.compare import Reader, line_model, line_sim

    monkeypatch.setattr(rig, "ELECTRODE_MM", rig.PITCH_MM)
    # a grid wider than the pad (the deep layer's load spreads to the pad's edge, past the array)
    monkeypatch.setattr(rig, "taxel_centres_mm", lambda: rig.PITCH_MM * (np.arange(20) - 9.5))
    reader = Reader(line_model(line_sim(SimConfig(), "bonded")))
    press = np.flatnonzero(committed["phase"] == 0)
    for line in ("superficial", "deep"):
        for i in press:
            args = (committed[f"{line}_xy_mm"], committed[f"{line}_kpa"][i], committed[f"{line}_w_mm2"])
            compressive = 2e-3 * float((np.clip(args[1], 0.0, None) * args[2]).sum())
            carried = reader.taxel_map(*args).sum() * rig.PITCH_MM ** 2 * 1e-3
            assert carried == pytest.approx(compressive, rel=s3.BALANCE_TOL), (line, i)
            half = reader.taxel_map(*args, half_y=False).sum() * rig.PITCH_MM ** 2 * 1e-3
            assert half != pytest.approx(compressive, rel=s3.BALANCE_TOL)


def test_the_taxel_map_refuses_areas_that_are_not_a_tensor_grids(committed):
    from layerskin_exp.sim.fem_reference.compare import Reader, line_model, line_sim

    reader = Reader(line_model(line_sim(SimConfig(), "bonded")))
    w = np.asarray(committed["deep_w_mm2"], float).copy()
    w[3] *= 2.0
    with pytest.raises(ValueError, match="tensor grid"):
        reader.taxel_map(committed["deep_xy_mm"], committed["deep_kpa"][0], w)


def _json_count_signals() -> dict:
    import json

    return json.loads((s3.DATA / "shear3d.json").read_text())["count_signals"]


def _same_signals(got: dict, want: dict) -> None:
    assert set(got) == set(want)
    for depth, row in want.items():
        if isinstance(row, str):
            assert got[depth] == row
            continue
        for name in s3.COUNT_SIGNALS:
            assert set(got[depth][name]) == set(want[depth][name])
            for side, summary in want[depth][name].items():
                if isinstance(summary, dict):
                    for k, v in summary.items():
                        assert got[depth][name][side][k] == pytest.approx(v, abs=1e-9), (depth, name, side, k)
                else:
                    assert got[depth][name][side] == pytest.approx(summary, abs=1e-9), (depth, name, side)


def test_the_3d_count_signals_are_what_the_shared_reader_reads(committed):
    """shear3d.json's count-CoP rows are the committed npz read through compare.Reader and
    alignment's taxel alignments (recomputed here from the committed data, no solve)."""
    want = _json_count_signals()
    assert any(not isinstance(r, str) for r in want.values()), "no branch of the 3D data reached F_x / F_z = 1/3"
    _same_signals(s3.count_signals_vs_section(committed, SimConfig()), want)


def test_the_count_signal_check_sees_a_misplaced_taxel_grid(committed, monkeypatch):
    """The 3D maps read with the taxel grid a quarter pitch off along x: the recomputed rows
    no longer match the committed ones."""
    from layerskin_exp.sim.fem_reference import alignment

    right = alignment.fem3d_signals
    monkeypatch.setattr(alignment, "fem3d_signals", lambda res, model, tx, ty: right(res, model, tx + 0.375, ty))
    with pytest.raises(AssertionError):
        _same_signals(s3.count_signals_vs_section(committed, SimConfig()), _json_count_signals())


def test_a_stuck_patch_peels_only_from_its_edge():
    """Of a stuck patch on the cap's surface, the nodes with a free neighbour may be released,
    the interior ones (whose neighbours are all stuck) may not."""
    fe = s3.Stack3D(SEC, x_edges=(-13.0, -1.0, 0.0, 1.0, 13.0), y_edges=(0.0, 1.0, 13.0))
    xy = fe.points[fe.contact.nodes, :2]
    stuck = (np.abs(xy[:, 0]) <= 1.0 + 1e-9) & (xy[:, 1] <= 1.0 + 1e-9)
    edge = fe._on_patch_edge(stuck)
    interior = stuck & (np.abs(xy[:, 0]) < 0.9) & (xy[:, 1] < 0.9)
    rim = stuck & (np.isclose(np.abs(xy[:, 0]), 1.0) | np.isclose(xy[:, 1], 1.0))
    assert interior.sum() >= 3 and rim.sum() >= 5
    assert not edge[interior].any()
    assert edge[rim].all()


def _branches_short_of_the_ratio(res: dict) -> list[float]:
    short = []
    for i in np.flatnonzero(res["phase"] == 0):
        depth = float(res["depth_mm"][i])
        mine = (res["phase"] == 1) & np.isclose(res["branch_depth_mm"], depth)
        if not mine.any() or (res["fx_n"][mine] / res["fz_n"][mine]).max() < s3.SHEAR_RATIO:
            short.append(depth)
    return short


def _unexplained(res: dict, stopped: dict) -> list[float]:
    """Branches short of F_x / F_z = 1/3 that shear3d.json's 'stopped' does not account for."""
    said = [float(k.split()[0]) for k in stopped if k.endswith(" mm")]
    loads = [float(k.split()[0]) for k in stopped if k.endswith(" N")]
    out = []
    for depth in _branches_short_of_the_ratio(res):
        i = int(np.flatnonzero((res["phase"] == 0) & np.isclose(res["depth_mm"], depth))[0])
        by_load = any(abs(res["fz_n"][i] / f - 1.0) <= s3.LOAD_TOL for f in loads)
        if not (any(np.isclose(depth, d) for d in said) or by_load):
            out.append(depth)
    return out


def test_every_3d_branch_reaches_the_ratio_or_says_where_it_stopped(committed):
    import json

    stopped = json.loads((s3.DATA / "shear3d.json").read_text())["stopped"]
    assert stopped == json.loads(str(committed["stopped"]))
    assert _unexplained(committed, stopped) == []
    # the check sees a reason that goes missing (a shear that stopped short; a press that stopped
    # recorded no branch, and the data must hold no press at its depth)
    sheared = [k for k, v in stopped.items() if v.startswith("shear stopped")]
    if sheared:
        assert _unexplained(committed, {k: v for k, v in stopped.items() if k != sheared[0]}) != []
    for k, v in stopped.items():
        if v.startswith("press stopped") and k.endswith(" mm"):
            assert not np.isclose(committed["depth_mm"][committed["phase"] == 0], float(k.split()[0])).any()



def _sticking_keeps(anchor_where) -> float:
    """Largest change of a contact node's force (N) when a pressed contact switches to sticking:
    three nodes penetrating a sphere of radius 2 mm by 0.01-0.03 mm."""
    from types import SimpleNamespace

    from layerskin_exp.sim.fem_reference.model import CapContact

    centre = np.array([0.0, 0.0, 4.0])
    down = np.array([[0.0, 0.0, -1.0], [0.15, 0.0, -1.0], [0.0, 0.2, -1.0], [1.0, 0.0, -0.2]])
    down /= np.linalg.norm(down, axis=1)[:, None]
    points = centre + (2.0 - np.array([0.01, 0.02, 0.03, -0.5]))[:, None] * down  # the last one off the cap
    contact = CapContact(np.arange(4), np.full(4, 0.25), 2.0, 50.0, dim=3)
    fe = SimpleNamespace(contact=contact, points=points, u=np.zeros_like(points), centre=centre)
    before = contact.forces(points, centre)[0]
    anchor_where(fe)
    return float(np.abs(contact.forces(points, centre)[0] - before).max())


def test_switching_to_sticking_keeps_the_presss_contact_forces():
    assert _sticking_keeps(s3.Stack3D.stick_all_in_contact) < 1e-12


def test_the_sticking_switch_check_sees_ties_anchored_inside_the_cap():
    """Anchored where each node is (inside the cap), the ties carry nothing at the switch: the
    press's normal force is lost (the 0.6 mm press lost 3.5 % of F_z at its first shear step)."""
    def where_it_is(fe):
        c = fe.contact
        d = fe.points[c.nodes] + fe.u[c.nodes] - fe.centre
        c.stuck[:] = c.radius - np.linalg.norm(d, axis=1) > 0
        c.anchor[c.stuck] = d[c.stuck]

    assert _sticking_keeps(where_it_is) > 1e-4


def _refinement() -> dict:
    import json

    return json.loads((s3.DATA / "shear3d_convergence.json").read_text())


@pytest.fixture(scope="module")
def refined():
    with np.load(s3.DATA / "refinement" / "shear3d.npz") as z:
        return {k: z[k] for k in z.files}


def test_the_3d_refinement_rows_are_what_the_committed_data_give(committed, refined):
    """shear3d_convergence.json against refinement3d on the two committed npz files: the refined
    mesh is finer, and every quantity's change is the data's."""
    conv = _refinement()
    assert int(refined["dof"]) > int(committed["dof"]) == conv["committed_dof"]
    got = s3.refinement3d(committed, refined, SimConfig(), depth=conv["depth_mm"])
    assert set(got["quantities"]) == set(conv["quantities"])
    for name, q in conv["quantities"].items():
        assert got["quantities"][name]["change"] == pytest.approx(q["change"], abs=1e-6), name
        assert got["quantities"][name]["converged"] == q["converged"], name
    # the count signals (through the taxel grid) are among them
    assert set(s3.COUNT_SIGNALS) <= set(conv["quantities"])


def _through_thickness() -> dict:
    import json

    return json.loads((s3.DATA / "shear3d_through_thickness.json").read_text())


def test_the_3d_through_thickness_rows_are_what_the_committed_data_give(committed):
    """shear3d_through_thickness.json against through_thickness3d on the committed npz files: each
    run has the elements it says through each layer, and every quantity's change is the data's."""
    import json

    tt = _through_thickness()
    by_name = {}
    for name, elements in s3.THROUGH_THICKNESS.items():
        with np.load(s3.DATA / "refinement" / f"shear3d_{name}.npz") as z:
            by_name[name] = {k: z[k] for k in z.files}
        assert json.loads(str(by_name[name]["elements"])) == {**s3.STACK_ELEMENTS, **elements}
        assert int(by_name[name]["dof"]) > int(committed["dof"])
    got = s3.through_thickness3d(committed, by_name, SimConfig(), depth=tt["depth_mm"])
    assert set(got["steps"]) == set(tt["steps"]) == set(s3.THROUGH_THICKNESS_STEPS)
    for step, want in tt["steps"].items():
        for name, q in want["quantities"].items():
            assert got["steps"][step]["quantities"][name]["change"] == pytest.approx(q["change"], abs=1e-6), (step, name)
            assert got["steps"][step]["quantities"][name]["converged"] == q["converged"], (step, name)


def test_the_mesh_error_adds_the_through_thickness_change():
    """A quantity converged in plane but not through the cover is not converged, and its error is
    the sum of the changes from the committed mesh (a step between two finer runs is not one of
    them); without the through-thickness study it is the in-plane change alone."""
    conv = {"quantities": {"fz_n": {"change": -0.04, "converged": True}}}
    through = {"steps": {"cover 1->2": {"from": None, "quantities": {"fz_n": {"change": -0.1, "converged": False}}},
                         "cover 2->4": {"from": "cover2", "quantities": {"fz_n": {"change": 0.5, "converged": False}}}}}
    assert s3.mesh_error3d(conv)["fz_n"] == {"change": 0.04, "converged": True}
    err = s3.mesh_error3d(conv, through)["fz_n"]
    assert err["change"] == pytest.approx(0.14) and not err["converged"]
    assert s3.uncovered3d(conv, {"plane_strain_mesh": {"fz_n": 0.1}}, through) == ["fz_n"]
    assert s3.uncovered3d(conv, {"plane_strain_mesh": {"fz_n": 0.15}}, through) == []


@pytest.mark.xfail(strict=True, reason=(
    "measured with the crossed laminate's sheet, in plane and through the cover: the contact half-width's "
    "mesh error is 0.73 against the 0.39 recorded, the superficial count CoP's 0.29 against 0.23 mm; the "
    "yardstick's bands for those two rows are narrower than its measured mesh error"))
def test_every_3d_quantity_converged_or_its_mesh_error_is_recorded():
    from layerskin_exp.sim.fem_reference.compare import load_tolerances

    assert s3.uncovered3d(_refinement(), load_tolerances(), _through_thickness()) == []


def test_the_3d_mesh_error_check_sees_a_larger_change():
    """Each quantity's in-plane change pushed past what is recorded for it (a converged one past
    its limit too): the check fails for every one."""
    from layerskin_exp.sim.fem_reference.compare import load_tolerances

    conv = _refinement()
    recorded = load_tolerances()["plane_strain_mesh"]
    worse = {"quantities": {n: {**q, "change": np.sign(q["change"] or 1.0) * (2.0 * abs(q["change"]) + recorded.get(n, 0.0) + 0.1),
                                "converged": False}
                            for n, q in conv["quantities"].items()}}
    assert len(s3.uncovered3d(worse, load_tolerances(), _through_thickness())) == len(conv["quantities"])
    tt = _through_thickness()
    doubled = {"steps": {k: {**step, "quantities": {n: {**q, "change": 2.0 * q["change"] + 0.1 * np.sign(q["change"] or 1.0)}
                                                     for n, q in step["quantities"].items()}}
                         for k, step in tt["steps"].items()}}
    assert set(s3.uncovered3d(conv, load_tolerances(), doubled)) >= {"fz_n", "max_lattice_strain", "peak_deep_kpa"}


@pytest.fixture(scope="module")
def load_branch():
    with np.load(s3.DATA / "shear3d_load_branch.npz") as z:
        return {k: z[k] for k in z.files}


def test_the_load_branch_is_the_study_load_with_a_volume_keeping_cover(load_branch):
    """The committed branch is what shear3d.LOAD_BRANCH says: pressed sticking to 3 N within
    LOAD_TOL, the cover at nu 0.499, on the refined mesh; it balances and was sheared."""
    import json

    sec = json.loads(str(load_branch["section"]))
    assert sec["cover_nu"] == s3.LOAD_BRANCH["cover_nu"]
    assert bool(load_branch["sticking_press"])
    press = load_branch["phase"] == 0
    assert press.sum() == 1
    assert abs(load_branch["fz_n"][press][0] / 3.0 - 1.0) <= s3.LOAD_TOL
    assert int(load_branch["dof"]) > 10_000  # the refined mesh (the committed coarse one: ~6k)
    s3.require_balance3d(load_branch, log=lambda *_: None)
    sheared = load_branch["phase"] == 1
    assert sheared.any() and np.all(load_branch["fx_n"][sheared] > 0)


def test_the_load_branch_rows_are_what_its_data_give(load_branch):
    import json

    committed = json.loads((s3.DATA / "shear3d_load_branch.json").read_text())
    assert committed["branches"] == json.loads(json.dumps(s3.load_branch3d(load_branch)))
    assert committed["stopped"] == json.loads(str(load_branch["stopped"]))


def _first_step_over_closed_form(res: dict, closed_form=s3.series_shear_stiffness) -> float:
    """The first sheared state's secant stiffness F_x / travel over the closed form's."""
    import json

    sec = Section(**json.loads(str(res["section"])))
    j = int(np.flatnonzero(res["phase"] == 0)[0])
    k = closed_form(sec, 0.5 * float(res["contact_to_mm"][j] - res["contact_from_mm"][j]), float(res["contact_y_mm"][j]))
    i = int(np.flatnonzero(res["phase"] == 1)[0])
    return float(res["fx_n"][i] / res["cap_x_mm"][i] / k["series_n_per_mm"])


# the tolerances' band for stiffness-like quantities (fem_reference/tolerances.yaml: a factor of 1.5)
STIFFNESS_BAND = (0.67, 1.5)


@pytest.mark.xfail(strict=True, reason=(
    "measured: the first 0.15 mm of cap travel carries 0.0033 N, 0.12 of the series closed form (0.175 N/mm); "
    "the secants at 0.65 and 1.15 mm are 0.87 and 1.03 of it"))
def test_the_load_branchs_shear_stiffness_is_the_cover_patch_and_the_lattice_in_series(load_branch):
    """At 3 N the cap's tangential load reaches the sheet through the cover's shear under the
    contact patch, in series with the lattice's shear over the pad."""
    assert STIFFNESS_BAND[0] <= _first_step_over_closed_form(load_branch) <= STIFFNESS_BAND[1]


@pytest.mark.parametrize("injected", ["lattice only", "cover over the pad", "cover twice as thick"])
def test_the_series_stiffness_check_sees_a_missing_or_wrong_spring(load_branch, injected):
    def wrong(sec, a_x, a_y):
        if injected == "lattice only":
            k = s3.series_shear_stiffness(sec, a_x, a_y)
            return {**k, "series_n_per_mm": k["lattice_n_per_mm"]}
        if injected == "cover over the pad":
            half = 0.5 * sec.width_mm
            return s3.series_shear_stiffness(sec, half, half)
        import dataclasses

        return s3.series_shear_stiffness(dataclasses.replace(sec, cover_mm=2 * sec.cover_mm), a_x, a_y)

    ratio = _first_step_over_closed_form(load_branch, wrong)
    assert not STIFFNESS_BAND[0] <= ratio <= STIFFNESS_BAND[1], ratio


def test_the_fast_model_is_compared_with_the_load_branch_on_its_own_figures(load_branch):
    from layerskin_exp.sim.fem_reference import compare as fc

    tol = fc.load_tolerances()
    rows = s3.load_branch_rows(SimConfig(), tol)
    assert [r.metric for r in rows] == list(s3.LOAD_BRANCH_METRICS.values())
    by = {r.metric: r for r in rows}
    j = int(np.flatnonzero(load_branch["phase"] == 0)[0])
    i = int(np.flatnonzero(load_branch["phase"] == 1)[0])
    travel = float(load_branch["cap_x_mm"][i])
    assert by["line_load_at_depth"].fem == float(load_branch["fz_n"][j])
    assert by["tangential_stiffness"].fem == pytest.approx(float(load_branch["fx_n"][i]) / travel)
    assert by["sheet_share_of_travel"].fem == pytest.approx(float(load_branch["sheet_shift_mm"][i]) / travel)
    assert (by["tangential_stiffness"].lo, by["tangential_stiffness"].hi) == tuple(tol["ratio"]["tangential_stiffness"])
    # the fast model was pressed to the branch's load, not its depth
    rec = s3.fast_at_load_branch(SimConfig(), load_branch)
    assert next(iter(rec.values()))["fast_fz_n"] == pytest.approx(float(load_branch["fz_n"][j]), rel=1e-3)


# which load-branch rows see each error of tests/sim/fem_injections.py (the others move none of them
# out of its band at 3 N)
LOAD_BRANCH_INJECTIONS = {"cover rigid in shear": ("tangential_stiffness", "sheet_share_of_travel"),
                          "lattice 10x too stiff in shear": ("tangential_stiffness", "sheet_share_of_travel"),
                          "sheet 100x too stiff in bending": ("line_load_at_depth",)}


# the cover's shear is the compliant link at 3 N (0.33 N/mm over its contact, the lattice 1.0), so
# a lattice 10x too stiff moves the series stiffness by 1.27x only: the sheet's share sees it
_LOAD_BRANCH_BLIND = {("lattice 10x too stiff in shear", "tangential_stiffness"): (
    "measured: the fast tangential stiffness at the load branch moves 0.245 -> 0.310 N/mm (1.27x, band "
    "[0.67, 1.5]) under a lattice 10x too stiff in shear: the cover's traction (0.33 N/mm) is in series")}


@pytest.mark.parametrize("error,metric", [
    pytest.param(e, m, marks=pytest.mark.xfail(strict=True, reason=_LOAD_BRANCH_BLIND[(e, m)]))
    if (e, m) in _LOAD_BRANCH_BLIND else (e, m)
    for e, metrics in LOAD_BRANCH_INJECTIONS.items() for m in metrics])
def test_each_load_branch_row_sees_an_error_of_the_fast_model(error, metric, monkeypatch):
    from layerskin_exp.sim import skin
    from layerskin_exp.sim.fem_reference import compare as fc
    from tests.sim.fem_injections import INJECTIONS

    patch, hook, _ = INJECTIONS[error]

    tol = fc.load_tolerances()
    monkeypatch.setattr(skin, "_TABLE_CACHE", {})
    base = {r.metric: r for r in s3.load_branch_rows(SimConfig(), tol)}
    if patch is not None:
        patch(monkeypatch)
    monkeypatch.setattr(skin, "_TABLE_CACHE", {})
    got = {r.metric: r for r in s3.load_branch_rows(SimConfig(), tol, model_hook=hook)}
    b, g = base[metric], got[metric].fast
    moved = abs(g - b.fast) > b.hi if b.kind == "difference" else not b.lo <= g / b.fast <= b.hi
    assert moved, (error, metric, b.fast, g)


def test_the_sheets_squeeze_is_its_bending_couple_along_its_curvature():
    """shear3d._sheet_squeeze on prescribed deflections: a bowl of uniform curvature kappa pressed
    and then tilted by theta across the pad has first moment int (M0 grad w1)_x dA / d =
    -D (1 + nu) kappa theta A / d over the whole pad (the half-model reports half), the tilt fitted
    exactly; a rigidity or lever taken wrong shows in the figure."""
    fe = s3.Stack3D(SEC, x_edges=(-13.0, -1.0, 0.0, 1.0, 2.0, 13.0), y_edges=(0.0, 1.0, 13.0))
    x, y = fe.points[:, 0], fe.points[:, 1]
    kappa, theta = 0.01, 0.002
    u0 = np.zeros_like(fe.points)
    u0[:, 2] = -0.5 * kappa * (x**2 + y**2)  # w = -u_z, sagging upward: kappa_ij = -grad grad w = -kappa I
    u = u0.copy()
    u[:, 2] -= theta * x
    got = s3._sheet_squeeze(fe, u0, u)
    t = 2 * SEC.film_mm + SEC.core_mm
    rigidity = s3.merged_sheet_e_mpa(SEC) * t**3 / (12 * (1 - 0.34**2))
    pad = SEC.width_mm * SEC.width_mm
    want = 0.5 * -rigidity * (1 + 0.34) * kappa * theta * pad / (2 * t / 3)
    assert got["tilt_slope"] == pytest.approx(theta, rel=1e-9)
    assert got["cross_terms"] == pytest.approx(want, rel=1e-6)
    assert got["tilt_term"] == pytest.approx(want, rel=1e-6)


def test_the_committed_squeeze_study_accounts_for_the_mid_planes_excess():
    """reference/shear3d_squeeze.json (`--shear3d-squeeze`): at each sheared state the mid-plane's
    first moment beyond its faces' mean is the films' squeeze from the sheet's own deflection, the
    closed form within a quarter of the excess (its finite differences on the committed mesh), and
    the excess is there to explain (with the crossed laminate's bending stiffness it is a tenth of
    the faces' travel at 0.3 mm: 0.069 of 0.72 mm)."""
    import json

    study = json.loads((s3.DATA / "shear3d_squeeze.json").read_text())
    states = [st for branch in study["branches"] for st in branch["states"]]
    assert len(states) == sum(len(t) for t in s3.SQUEEZE_BRANCHES.values())
    for st in states:
        excess = st["mid_plane_excess_mm"]
        assert excess > 0.05 * st["cop_faces_mean_mm"]
        # (each CoP over its own plane's load: the planes carry F_z alike within the balance's 1e-4)
        assert st["cop_mid_plane_mm"] == pytest.approx(st["cop_faces_mean_mm"] + excess, abs=1e-3)
        assert st["squeeze_closed_form_mm"] == pytest.approx(excess, rel=0.25)


def _diagonal_study() -> dict:
    import json

    return json.loads((s3.DATA / "shear3d_diagonal.json").read_text())


def test_the_whole_pad_is_the_half_model_doubled():
    """reference/shear3d_diagonal.json (`--shear3d-diagonal`): the whole pad sheared along x
    carries the half-model's force at the same travel (the committed 0.3 mm branch, interpolated),
    and every layer carries F_z."""
    study = _diagonal_study()
    res = dict(np.load(s3.DATA / "shear3d.npz"))
    on = (res["phase"] == 1) & np.isclose(res["branch_depth_mm"], study["depth_mm"])
    half_fx = np.interp(s3.DIAGONAL_TRAVEL_MM, res["cap_x_mm"][on], res["fx_n"][on])
    along_x = study["branches"]["along x"]
    assert along_x["ft_n"]["along"] == pytest.approx(half_fx, rel=s3.DIAGONAL_TOL)
    for branch in study["branches"].values():
        for balance in branch["balance"].values():
            assert balance == pytest.approx(1.0, abs=s3.BALANCE_TOL)


def test_the_homogenised_lattice_answers_a_diagonal_shear_as_an_axial_one():
    """The same travel along the diagonal and along x from one press: the tangential force and F_z
    within DIAGONAL_TOL, each layer's CoP travel and the sheet's within DIAGONAL_POS_TOL_MM, and
    nothing across the shear (the transversely isotropic lattice, the square pad's symmetry)."""
    study = _diagonal_study()
    diff = study["diagonal_minus_x"]
    assert abs(diff["ft_relative"]) <= s3.DIAGONAL_TOL
    assert abs(diff["fz_relative"]) <= s3.DIAGONAL_TOL
    for k in ("superficial_cop_travel_mm", "deep_cop_travel_mm", "sheet_travel_mm"):
        assert abs(diff[k]) <= s3.DIAGONAL_POS_TOL_MM
    for branch in study["branches"].values():
        assert abs(branch["ft_n"]["across"]) <= s3.DIAGONAL_TOL * branch["ft_n"]["along"]
        for k in ("superficial_cop_travel_mm", "deep_cop_travel_mm", "sheet_travel_mm"):
            assert abs(branch[k]["across"]) <= s3.DIAGONAL_POS_TOL_MM
