"""The 3D check of the section's shear (issue 28, item 6): the hemispherical cap on the stack as a
solid, pressed to SHEAR_FROM_MM and to the study's normal loads LOADS_N, and from each sheared
with the contact sticking to F_x / F_z = 1/3.

What is modelled (lengths mm, stresses MPa, forces N):
- a half-model, y >= 0, with u_y = 0 on the symmetry plane y = 0 (a press at x = 0 and a shear
  along +x keep that symmetry); forces are reported for the whole skin (twice the half's);
- tri-quadratic hexahedra (hex27), graded in x and y; the committed run's mesh is X_EDGES_MM x
  Y_EDGES_MM (0.5 mm under the cap, 6k degrees of freedom; see there why not finer);
- each FSR sheet (film, Velostat core, film) merged into one isotropic layer of the sheet's
  thickness whose bending stiffness is the crossed laminate's about its neutral axis
  (`merged_sheet_e_mpa`: one face the along-strip film, the other the across-strip one, 5.3 N mm
  before the plate's 1 / (1 - nu^2)); its membrane stiffness is then 10 % under the laminate's
  (1840 against 2050 N/mm);
- the lattice homogenised as a transversely isotropic solid: a compressible neo-Hooke matrix
  (nu = 0) with shear modulus the honeycomb's G13 = rho G_s / 2, plus a term k / 8 (s - 1)^2 on
  the squared stretch s of the separation of planes z = const (model.plane_separation: a fibre's
  W in uniaxial stretch, but no shear coupling), so that the through-thickness modulus is the
  honeycomb's E3 = rho E_s (Gibson & Ashby 1997, sec. 4.4; Section.honeycomb_moduli_kpa). Its in-plane
  moduli are the matrix's, 2 G13 = rho E_s / 3 (a regular honeycomb's in-plane E is
  ~2.3 rho^3 E_s, 0.2 E_s at rho = 0.44: the same order);
- the cover as in the section; the cap a rigid sphere (model.CapContact with dim = 3, each
  surface node's weight its area, penalty 50 N/mm^3: ~300 times the cover's own foundation
  stiffness E / t), frictionless while pressing (Newton on a fixed active set, the set updated
  between solves), sticking while shearing: a node that touches sticks to the cap's surface point
  nearest it (so a tie carries the penetration's normal force, as the press did), and a stuck
  node whose tie pulls (tension) is released only on the stuck patch's edge, then slides
  (frictionless) until it lifts off or the step ends.

Where the 3D branches stop (measured with the sheet's earlier bending stiffness, twice the
laminate's; with the laminate's the frictionless press stalls past 0.4 mm, MID_BRANCH):
the cover's neo-Hooke holds a volume change with K / 2 (J - 1)^2, K = E / 3(1 - 2 nu) = 0.58 MPa
at the simulator's nu 0.49, so it carries at most ~K of pressure and gives up its volume beyond.
The section's cover keeps J >= 0.78 to 1.2 mm (its peak contact pressure 197 kPa); in 3D the cap's
pressure is higher (peak superficial 543 kPa at 0.6 mm, ~1.7 MPa at 3 N) and the cover's smallest
volume ratio under the cap is 0.36 / 0.10 / 0.05 at 0.3 mm / 0.6 mm / 3 N: the contact stops
spreading (a sticking press: half-width 1.07 mm from 0.6 mm to 3 N) and the crushed elements
defeat Newton under any tangential motion, full stick or Coulomb friction (mu 1, tried). A cover
that holds its volume (nu -> 0.5 with a mixed formulation, or a volumetric law that does not
saturate) and a mesh that resolves the crushed zone are what the 3 N branch needs. The section's
own sensitivity to the cover's nu: `--cover-poisson` (cover_compressibility.json).

With such a cover (nu 0.499), pressed sticking on the refined mesh (LOAD_BRANCH,
`--shear3d-load-branch`), the 3 N press holds (cover J >= 0.43) and shears, and it says why 1/3
is out of reach at the study's load: the contact patch hardly grows with load (the membrane-stiff
sheet sinks with the cap into the lattice; half-width 1.13 mm at 0.83 N and at 3 N), so the
cap's tangential load reaches the sheet only through the cover's shear over that patch, in series
with the lattice's shear over the pad (series_shear_stiffness, 0.175 N/mm at 3 N). F_x / F_z = 1/3
then needs 5.7 mm of cap travel and a mean cover shear strain of 21 (shear3d_load_branch.json),
far past where these elements (or the silicone) hold; the branch's Newton stops at 1.28 mm
(F_x / F_z 0.081).

Each layer's load is read as in the section: the internal forces of the elements above a node
plane, at its nodes, over the nodes' tensor-Simpson areas. Every layer's sum must carry F_z
within BALANCE_TOL, or the run fails. The shear signals are read from those maps as the
section's are: through the taxel grid and the simulator's FSR law (compare.Reader.taxel_map,
alignment.fem3d_signals), averaged over the grid's alignments (count_signals_vs_section).
"""

from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path

import felupe as fem
import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from layerskin_exp.sim.fem_reference.compare import SHEAR_RATIO, at_ratio
from layerskin_exp.sim.fem_reference.model import (
    KPA,
    CapContact,
    Section,
    _neo_hooke,
    homogenised_lattice,
    moment_scale,
    simpson_weights,
)

DATA = Path(__file__).resolve().parent / "reference"
SHEAR_FROM_MM = (0.3, 0.6)
# the study's normal loads (it presses to 3-6 N): branches pressed to F_z = each, within LOAD_TOL
LOADS_N = (3.0,)
LOAD_TOL = 0.02
PRESS_STEP_MM = 0.2
SHEAR_STEPS = 10  # secant advances of the cap per branch, each at most 0.5 mm
# the cap's largest step while shearing: a node that comes into contact sticks where it is found
# after a step, so the step is how finely the stick front advances (it was 0.25 mm). At 0.3 mm,
# F_x / F_z at 0.8 mm of travel was 0.3329 / 0.3354 / 0.3378 in steps of 0.1 / 0.05 / 0.025 mm
# (0.7 % per halving; measured before stick_all_in_contact kept the press's normal force)
SHEAR_STEP_MM = 0.05
BALANCE_TOL = 0.02
# the moment balance is exact for converged equilibria (consistent nodal forces carry first
# moments exactly); the section's check allows the same (model.StackFE.state, tests)
MOMENT_TOL = 0.01
FINE_X_MM = (-1.05, 1.75)  # the cap's contact and its shear travel
FINE_Y_MM = 1.05
FINE_H_MM = 0.35
OUTER_MM = (0.7, 1.75, 3.5)  # element sizes outside the fine zone, then one to the pad's edge
LINES = ("superficial", "deep", "interface", "base")
FACES = ("sheet_top", "sheet_bottom")  # the superficial sheet's faces (Stack3D.line_z)
# The committed run's mesh: the graded one above (0.35 mm, 20k DOF) costs ~10 s a factorisation
# on this machine's shared cores and the contact's active set needs ~100 of them per 0.3 mm of
# press, so the run here uses this coarse one (0.5 mm under the cap, 6k DOF). Its error at the
# 0.3 mm branch is measured against REFINED_X_EDGES_MM x REFINED_Y_EDGES_MM
# (shear3d_convergence.json) and recorded in tolerances.yaml's `plane_strain_mesh:`.
X_EDGES_MM = (-13.0, -4.0, -1.5, -0.5, 0.0, 0.5, 1.5, 4.0, 13.0)
Y_EDGES_MM = (0.0, 0.5, 1.5, 4.0, 13.0)
# The refinement of the 3D model (`--shear3d-refinement`): every element of the committed mesh
# within 1.5 mm of the cap's axis in x and y halved (0.25 mm under the cap, 13k DOF), the press
# to REFINEMENT_DEPTH_MM and its shear solved again. The coarser elements outside, and the
# through-thickness elements, are the committed mesh's (those are refined on their own below).
REFINED_X_EDGES_MM = (-13.0, -4.0, -1.5, -1.0, -0.5, -0.25, 0.0, 0.25, 0.5, 1.0, 1.5, 4.0, 13.0)
REFINED_Y_EDGES_MM = (0.0, 0.25, 0.5, 1.0, 1.5, 4.0, 13.0)
REFINEMENT_DEPTH_MM = 0.3
# The committed mesh's elements through each layer's thickness (hex27). `--shear3d-through-thickness`
# solves the same branch with the layers of each THROUGH_THICKNESS entry in more elements (the
# in-plane mesh is the committed one) and judges each step of THROUGH_THICKNESS_STEPS:
# reference/shear3d_through_thickness.json. Its steps from the committed mesh (`from` None) add to
# the in-plane refinement's changes in mesh_error3d.
STACK_ELEMENTS = {"deep_sheet": 2, "lattice": 2, "sheet": 2, "cover": 1}
THROUGH_THICKNESS = {"cover2": {"cover": 2}, "cover4": {"cover": 4},
                     "sheets_lattice4": {"deep_sheet": 4, "lattice": 4, "sheet": 4}}
THROUGH_THICKNESS_STEPS = {"cover 1->2": (None, "cover2"), "cover 2->4": ("cover2", "cover4"),
                           "sheets and lattice 2->4": (None, "sheets_lattice4")}


def graded_edges(lo: float, hi: float, fine: tuple[float, float], h: float, outer=OUTER_MM) -> np.ndarray:
    """Element edges from lo to hi: size h over `fine`, then the `outer` sizes, then the rest."""
    mid = np.linspace(fine[0], fine[1], int(round((fine[1] - fine[0]) / h)) + 1)
    right, left = [fine[1]], [fine[0]]
    for s in outer:
        if right[-1] + s < hi - 1e-9:
            right.append(right[-1] + s)
        if left[-1] - s > lo + 1e-9:
            left.append(left[-1] - s)
    right.append(hi)
    left.append(lo)
    edges = np.concatenate([left[::-1][:-1], mid, right[1:]]) if fine[0] > lo else np.concatenate([mid, right[1:]])
    return np.unique(np.round(edges, 12))


def laminate_bending_n_mm(sec: Section) -> float:
    """Bending stiffness (N mm, E I per width, without the plate's 1 / (1 - nu^2)) of one FSR
    sheet as laminated: the along-strip film on one face, the core, the across-strip film on the
    other (the strips of the two films are crossed, so bent about either axis one face is stiff and
    the other soft), about the laminate's neutral axis, which lies near the stiff face."""
    tf, tc = sec.film_mm, sec.core_mm
    layers = ((sec.film_across_e_mpa, tf), (sec.core_e_mpa, tc), (sec.film_along_e_mpa, tf))
    z, mid = 0.0, []
    for _, t in layers:
        mid.append(z + 0.5 * t)
        z += t
    neutral = sum(e * t * m for (e, t), m in zip(layers, mid, strict=True)) / sum(e * t for e, t in layers)
    return sum(e * (t ** 3 / 12 + t * (m - neutral) ** 2) for (e, t), m in zip(layers, mid, strict=True))


def merged_sheet_e_mpa(sec: Section) -> float:
    """Young's modulus of one layer of the sheet's thickness with the crossed laminate's bending
    stiffness (`laminate_bending_n_mm`)."""
    t = 2 * sec.film_mm + sec.core_mm
    return 12 * laminate_bending_n_mm(sec) / t ** 3


def lattice_material(sec: Section):
    return homogenised_lattice(sec, axis=2)


def stack(sec: Section, elements: dict | None = None) -> list[tuple[str, float, int]]:
    """The layers from the base up: name, thickness (mm) and elements through it (STACK_ELEMENTS,
    updated by `elements`)."""
    n = {**STACK_ELEMENTS, **(elements or {})}
    sheet = 2 * sec.film_mm + sec.core_mm
    return [("deep_sheet", sheet, n["deep_sheet"]), ("lattice", sec.lattice_mm, n["lattice"]),
            ("sheet", sheet, n["sheet"]), ("cover", sec.cover_mm, n["cover"])]


class Stack3D:
    """The half-model, its bodies and a Newton solver with the sphere's contact."""

    def __init__(self, sec: Section, penalty: float = 50.0, x_edges=None, y_edges=None, elements: dict | None = None,
                 symmetric: bool = True):
        """symmetric: the half-model y >= 0 with u_y = 0 on y = 0 (forces reported twice the
        half's); False: the whole pad (y_edges then span it), for loads off the x axis."""
        self.sec = sec
        self.copies = 2 if symmetric else 1
        layers = stack(sec, elements)
        self.elements = {name: n for name, _, n in layers}
        half = 0.5 * sec.width_mm
        self.xe = graded_edges(-half, half, FINE_X_MM, FINE_H_MM) if x_edges is None else np.asarray(x_edges)
        self.ye = graded_edges(0.0, half, (0.0, FINE_Y_MM), FINE_H_MM) if y_edges is None else np.asarray(y_edges)
        ze, self.layer_z, lay_rows = [0.0], {}, []
        for name, t, n in layers:
            self.layer_z[name] = (ze[-1], ze[-1] + t)
            ze += list(ze[-1] + np.linspace(0, t, n + 1)[1:])
            lay_rows += [name] * n
        self.ze = np.array(ze)
        grid = fem.Grid(self.xe, self.ye, self.ze)
        pts, cells, ctype = fem.mesh.convert(grid.points, grid.cells, grid.cell_type, order=2, calc_points=True,
                                             calc_midfaces=True, calc_midvolumes=True)
        self.points, self.cells = pts, cells
        zc = pts[cells[:, :8], 2].mean(axis=1)
        row = np.searchsorted(self.ze, zc) - 1
        self.cell_layer = np.array(lay_rows)[row]
        self.height_mm = float(self.ze[-1])
        mats = {"deep_sheet": _neo_hooke(merged_sheet_e_mpa(sec), 0.34), "sheet": _neo_hooke(merged_sheet_e_mpa(sec), 0.34),
                "lattice": lattice_material(sec), "cover": _neo_hooke(sec.cover_e_mpa, sec.cover_poisson())}
        self._first = None
        self.bodies = []
        for name, umat in mats.items():
            mask = self.cell_layer == name
            self.bodies.append((mask, *self._body(mask, umat)))
        n = len(pts)
        self.u = np.zeros((n, 3))
        fixed = np.zeros((n, 3), bool)
        fixed[np.isclose(pts[:, 2], 0.0)] = True
        if symmetric:
            fixed[np.isclose(pts[:, 1], 0.0), 1] = True
        self.free = np.flatnonzero(~fixed.ravel())
        top, w = self.plane(self.height_mm)
        self.contact = CapContact(top, w, sec.radius_mm, penalty, dim=3)
        self.centre = np.array([0.0, 0.0, self.height_mm + sec.radius_mm])
        self.max_step_mm = 0.15
        self.newton_tol = 1e-5  # of the first iterate's contact force: ~1e-3 of the load
        self._probes = {}
        self.factorisations, self.factor_seconds = 0, 0.0
        self.verbose = False

    def _body(self, mask, umat):
        region = fem.RegionTriQuadraticHexahedron(fem.Mesh(self.points, self.cells[mask], "hexahedron27"))
        fld = fem.FieldContainer([fem.Field(region, dim=3)])
        if self._first is None:
            self._first = fld
        else:
            fld.link(self._first)
        return fem.SolidBody(umat, fld), fld

    def plane(self, z_mm: float) -> tuple[np.ndarray, np.ndarray]:
        """The nodes on the plane z = z_mm and their areas (tensor Simpson; the y = 0 edge's nodes
        half a strip, as the half-model has it)."""
        on = np.flatnonzero(np.isclose(self.points[:, 2], z_mm, atol=1e-9))
        if len(on) == 0:
            raise ValueError(f"no node plane at z = {z_mm} mm")
        xn = np.empty(2 * len(self.xe) - 1)
        xn[0::2], xn[1::2] = self.xe, 0.5 * (self.xe[:-1] + self.xe[1:])
        yn = np.empty(2 * len(self.ye) - 1)
        yn[0::2], yn[1::2] = self.ye, 0.5 * (self.ye[:-1] + self.ye[1:])
        ix = np.argmin(np.abs(self.points[on, 0][:, None] - xn[None]), axis=1)
        iy = np.argmin(np.abs(self.points[on, 1][:, None] - yn[None]), axis=1)
        return on, simpson_weights(self.xe)[ix] * simpson_weights(self.ye)[iy]

    def _sync(self):
        self._first[0].values[:] = self.u

    def _system(self):
        n = self.u.size
        self._sync()
        r = np.zeros(n)
        K = sp.csr_matrix((n, n))
        for _, body, fld in self.bodies:
            r += np.asarray(body.assemble.vector(fld).todense()).ravel()
            K = K + body.assemble.matrix(fld)
        c = self.contact
        x = self.points[c.nodes] + self.u[c.nodes]
        f, k, normal = c.forces(x, self.centre)
        dof = 3 * c.nodes[:, None] + np.arange(3)
        np.subtract.at(r, dof.ravel(), f.ravel())
        rows = np.repeat(dof, 3, axis=1).ravel()
        cols = np.tile(dof, (1, 3)).ravel()
        K = K + sp.csr_matrix((k.ravel(), (rows, cols)), shape=(n, n))
        return r, K, f, normal

    def newton(self, max_iter: int = 40) -> int:
        """Equilibrium at the cap's current position (a factorisation costs seconds at 20k DOF:
        it is kept while the residual falls by half an iteration or faster, a modified Newton)."""
        scale, lu, last = None, None, np.inf
        for it in range(1, max_iter + 1):
            r, K, f, _ = self._system()
            rf = r[self.free]
            if scale is None:
                scale = max(np.abs(f).sum(), 1e-6)
            norm = float(np.linalg.norm(rf))
            if norm < self.newton_tol * scale and it > 1:
                return it
            if not np.all(np.isfinite(rf)):
                raise FloatingPointError("inverted element")
            if lu is None or norm > 0.5 * last:
                t0 = time.process_time()
                # the tangent is symmetric and positive definite (neo-Hooke bodies, penalty ties):
                # a symmetric ordering without pivoting halves the fill and the time (1.5 s
                # against 3.6 s at 13k DOF)
                lu = splu(K[self.free][:, self.free].tocsc(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                          options={"SymmetricMode": True})
                self.factor_seconds += time.process_time() - t0
                self.factorisations += 1
            last = norm
            if self.verbose:
                print(f"    newton {it}: |r| {norm:.3g} (scale {scale:.3g}), {self.factorisations} factorisations", flush=True)
            du = lu.solve(-rf)
            if not np.all(np.isfinite(du)):
                raise FloatingPointError("singular tangent")
            big = np.abs(du).max()
            if big > self.max_step_mm:
                du *= self.max_step_mm / big
            flat = self.u.reshape(-1)
            # backtracking: a step that raises the residual (a contact node flipping in and out at
            # the contact's edge) is halved, up to three times, and the tangent renewed
            base = flat[self.free].copy()
            for _ in range(3):
                flat[self.free] = base + du
                if np.linalg.norm(self._residual()[self.free]) <= norm:
                    break
                du *= 0.5
                lu = None
            if np.abs(du).max() < 1e-10 * max(1.0, np.abs(flat).max()) and it > 2:
                return it
        raise RuntimeError(f"no convergence in {max_iter} iterations (|r| = {np.linalg.norm(rf):.3g})")

    def _residual(self) -> np.ndarray:
        self._sync()
        r = np.zeros(self.u.size)
        for _, body, fld in self.bodies:
            r += np.asarray(body.assemble.vector(fld).todense()).ravel()
        c = self.contact
        f = c.forces(self.points[c.nodes] + self.u[c.nodes], self.centre)[0]
        np.subtract.at(r, (3 * c.nodes[:, None] + np.arange(3)).ravel(), f.ravel())
        return r

    def solve_at(self, centre, sticking: bool, max_active_passes: int = 4) -> int:
        self.centre = np.asarray(centre, float)
        total = 0
        c = self.contact
        if not sticking:
            # frictionless: Newton on a fixed active set (on/off switching of a node inside Newton
            # stalls it on this coarse surface), the set updated between solves
            x = self.points[c.nodes] + self.u[c.nodes]
            c.active = (c.radius - np.linalg.norm(x - self.centre, axis=1) > 0) & ~c.stuck
            for _ in range(3 * max_active_passes):
                total += self.newton()
                x = self.points[c.nodes] + self.u[c.nodes]
                gap = c.radius - np.linalg.norm(x - self.centre, axis=1)
                new, release = ~c.active & ~c.stuck & (gap > 0), c.active & (gap < 0)
                if not new.any() and not release.any():
                    return total
                c.active = (c.active | new) & ~release
            raise RuntimeError("the contact's active set does not settle")
        # the nodes released from a stick in this step slide: frictionless contact (c.active)
        # until they lift off, never stuck again within the step (a node released in tension
        # that penetrates again and re-sticks where it is found chattered in and out of the stuck
        # set, and Newton lost equilibrium on the 0.6 mm and 3 N branches)
        c.active = np.zeros(len(c.nodes), bool)
        for _ in range(2 * max_active_passes):
            total += self.newton()
            c = self.contact
            x = self.points[c.nodes] + self.u[c.nodes]
            _, _, normal = c.forces(x, self.centre)
            d = x - self.centre
            gap = c.radius - np.linalg.norm(d, axis=1)
            new = ~c.stuck & ~c.active & (gap > 0)
            # a stuck patch peels from its edge: a node whose surface neighbours are all stuck
            # cannot open a gap, and the small tension a tri-quadratic face's mid-side node can
            # carry under a sticking cap (the 9-node face's nodal-force pattern) is not one.
            # Freed (by hand, the 0.6 mm branch on the way from 0.4 to 0.65 mm of travel: the
            # node at x 0.25, y 0.5, -0.04 MPa), the next Newton step moved its neighbour 0.59 mm
            # and inverted elements.
            release = c.stuck & (normal < 0) & self._on_patch_edge(c.stuck)
            lift = c.active & (gap < 0)
            if not new.any() and not release.any() and not lift.any():
                return total
            c.anchor[new] = d[new] / np.linalg.norm(d[new], axis=1)[:, None] * c.radius
            c.stuck[new] = True
            c.stuck[release] = False
            c.active[release] = True
            c.active[lift] = False
        raise RuntimeError("the contact's stuck set does not settle")

    def _on_patch_edge(self, stuck: np.ndarray) -> np.ndarray:
        """Contact nodes with a surface neighbour (next node along x or y) that is not stuck."""
        if not hasattr(self, "_top_neighbours"):
            xy = self.points[self.contact.nodes, :2]
            ix = np.unique(np.round(xy[:, 0], 9), return_inverse=True)[1]
            iy = np.unique(np.round(xy[:, 1], 9), return_inverse=True)[1]
            at = {(a, b): k for k, (a, b) in enumerate(zip(ix, iy, strict=True))}
            self._top_neighbours = [[at[q] for q in ((a - 1, b), (a + 1, b), (a, b - 1), (a, b + 1)) if q in at]
                                    for a, b in zip(ix, iy, strict=True)]
        return np.array([not all(stuck[j] for j in nb) for nb in self._top_neighbours])

    def snapshot(self) -> tuple:
        """The equilibrium's state: displacements, the cap's centre and the contact's sets."""
        c = self.contact
        return (self.u.copy(), self.centre.copy(), c.stuck.copy(), c.anchor.copy(),
                None if c.active is None else c.active.copy())

    def restore(self, saved: tuple) -> None:
        c = self.contact
        self.u[:], self.centre = saved[0], saved[1].copy()
        c.stuck[:], c.anchor[:] = saved[2], saved[3]
        c.active = None if saved[4] is None else saved[4].copy()

    def move_to(self, centre, sticking: bool, step_mm: float, min_step_mm: float = 1e-3) -> int:
        target = np.asarray(centre, float)
        total, h = 0, step_mm
        while True:
            gap = target - self.centre
            dist = float(np.linalg.norm(gap))
            if dist < 1e-12:
                return total
            step = min(h, dist)
            saved = self.snapshot()
            try:
                with np.errstate(all="ignore"):
                    total += self.solve_at(self.centre + gap * (step / dist), sticking)
                h = min(step_mm, 1.5 * h)
            except (RuntimeError, FloatingPointError, np.linalg.LinAlgError):
                self.restore(saved)
                h = 0.5 * step
                if h < min_step_mm:
                    raise

    def stick_all_in_contact(self) -> None:
        """Start of the shear phase: every node in contact sticks to the cap's surface point
        nearest it (its penetration stays, so the tie pushes it out as the frictionless contact
        did and the press's F_z is kept). Tied where it was (inside the cap), each node lost its
        normal force at the switch: the 0.6 mm press's F_z fell 3.5 % at the first shear step,
        and at 3 N (larger penetrations under this penalty) no first step converged."""
        c = self.contact
        d = self.points[c.nodes] + self.u[c.nodes] - self.centre
        dist = np.linalg.norm(d, axis=1)
        on = c.radius - dist > 0
        c.stuck[:] = on
        c.anchor[on] = d[on] / dist[on, None] * c.radius

    def transmitted(self, z_mm: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Nodes on the plane z = z_mm, their areas, and the force (n, 3) the material below
        exerts through each on the material above (the internal forces of the row of elements
        above the plane, at its nodes)."""
        if z_mm not in self._probes:
            nodes, w = self.plane(z_mm)
            bottom = self.points[self.cells, 2].min(axis=1)
            above = np.isclose(bottom, z_mm, atol=1e-9)
            if not above.any():
                raise ValueError(f"no element row above z = {z_mm} mm")
            probes = [self._body(above & mask, body.umat) for mask, body, _ in self.bodies if (above & mask).any()]
            self._probes[z_mm] = (nodes, w, probes)
        nodes, w, probes = self._probes[z_mm]
        self._sync()
        f = np.zeros(self.u.size)
        for probe, fld in probes:
            f += np.asarray(probe.assemble.vector(fld).todense()).ravel()
        return nodes, w, f.reshape(-1, 3)[nodes]

    def plane_normals(self, nodes: np.ndarray) -> np.ndarray:
        """Unit normals (n, 3, pointing up) of a node plane (`plane`) where its nodes are now:
        the cross product of the deformed plane's tangents along x and y, by second-order
        differences on its tensor grid, mirrored across the symmetry plane y = 0 (there the
        tangent along y has no z part)."""
        ref = self.points[nodes]
        xs, ix = np.unique(np.round(ref[:, 0], 9), return_inverse=True)
        ys, iy = np.unique(np.round(ref[:, 1], 9), return_inverse=True)
        grid = np.full((len(xs), len(ys), 3), np.nan)
        grid[ix, iy] = ref + self.u[nodes]
        if np.isnan(grid).any():
            raise ValueError("the plane's nodes do not form a tensor grid")
        mirror = grid[:, :0:-1] * np.array([1.0, -1.0, 1.0])
        full = np.concatenate([mirror, grid], axis=1)
        yy = np.concatenate([-ys[:0:-1], ys])
        n = np.cross(np.gradient(full, xs, axis=0, edge_order=2), np.gradient(full, yy, axis=1, edge_order=2))
        n = n[:, len(ys) - 1:]
        n /= np.linalg.norm(n, axis=2, keepdims=True)
        return n[ix, iy]

    def line_z(self) -> dict:
        """The planes read: the sheets' mid-planes (what each layer's FSR reads), the lattice's
        base (interface), the model's base, and the superficial sheet's two faces (its top, under
        the cover, and its bottom, on the lattice: read along the sheet's normal, the mid-plane has
        their mean plus the squeeze of the sheet's bending couple along its curvature; its z
        component also has the sheet's transverse shear force where the sheet is tilted,
        `squeeze3d`)."""
        mid = {k: 0.5 * sum(self.layer_z[k]) for k in ("sheet", "deep_sheet")}
        return {"superficial": mid["sheet"], "deep": mid["deep_sheet"], "interface": self.layer_z["lattice"][0], "base": 0.0,
                "sheet_top": self.layer_z["sheet"][1], "sheet_bottom": self.layer_z["sheet"][0]}

    def state(self) -> dict:
        """The whole skin's forces (the half's times `copies`; F_z > 0 compressive), contact and per-layer
        pressure maps (kPa) at the current equilibrium."""
        _, _, f, normal = self._system()
        fx, fz = self.copies * float(f[:, 0].sum()), -self.copies * float(f[:, 2].sum())
        c = self.contact
        x_top = self.points[c.nodes] + self.u[c.nodes]
        on = normal > 1e-9
        out = {"cap_x_mm": float(self.centre[0]), "depth_mm": float(self.height_mm + self.sec.radius_mm - self.centre[2]),
               "fx_n": fx, "fz_n": fz,
               "contact_from_mm": float(x_top[on, 0].min()) if on.any() else np.nan,
               "contact_to_mm": float(x_top[on, 0].max()) if on.any() else np.nan,
               "contact_y_mm": float(x_top[on, 1].max()) if on.any() else np.nan,
               "contact_kpa": -f[:, 2] / c.weights / KPA,
               "stuck_fraction": float(c.stuck[on].mean()) if on.any() else 0.0}
        # where the load acts (the half's): its centroid along x and the height of its tangential
        # part; the cap's normal pressure passes through the cap's centre, so a tangential load
        # carried on the sunk cap's flank acts higher than the contact
        fxh, fzh = float(f[:, 0].sum()), -float(f[:, 2].sum())
        load_x = float((x_top[:, 0] * -f[:, 2]).sum() / fzh) if fzh else np.nan
        load_h = float((x_top[:, 2] * f[:, 0]).sum() / fxh) if abs(fxh) > 1e-6 * abs(fzh) else float(self.height_mm)
        out.update(load_x_mm=load_x, load_height_mm=load_h)
        for name, z in self.line_z().items():
            nodes, w, g = self.transmitted(z)
            out[f"{name}_kpa"] = g[:, 2] / w / KPA
            out[f"{name}_shear_kpa"] = g[:, 0] / w / KPA
            # what an FSR lying in the plane reads: the traction along its normal where it is now.
            # Where the plane is tilted the z component also carries part of the force along it
            # (a bent sheet's transverse shear force: slope times Q)
            out[f"{name}_normal_kpa"] = (g * self.plane_normals(nodes)).sum(axis=1) / w / KPA
            out[f"{name}_u_mm"] = self.u[nodes].copy()  # where the plane's nodes have moved
            # statics of everything above the plane, its nodes where they are now: the first
            # moment of the normal force through it is the load's, F_z x_load + F_x h_load, plus
            # that of the tangential force through it, sum(z g_x) (model.StackFE.state's check)
            y = self.points[nodes] + self.u[nodes]
            first, through = float((y[:, 0] * g[:, 2]).sum()), float(g[:, 2].sum())
            expected = fzh * load_x + fxh * load_h + float((y[:, 2] * g[:, 0]).sum())
            out[f"{name}_moment_error"] = (first - expected) / moment_scale(fzh, fxh, load_x, load_h)
            # the force CoP where the plane's nodes are now (the stored xy are their reference
            # positions, the layer's own frame)
            out[f"{name}_cop_world_mm"] = first / through if through else np.nan
        sheet = self.plane(self.line_z()["superficial"])[0]
        out["sheet_shift_mm"] = float(self.u[sheet[np.abs(self.points[sheet, 0]) < 1.0], 0].mean())
        # the superficial core's mid-plane point (reference x, its own frame) now under the cap,
        # on the symmetry plane: what the section's sheet_x_under_cap_mm is
        mid = sheet[np.isclose(self.points[sheet, 1], 0.0)]
        mid = mid[np.argsort(self.points[mid, 0])]
        out["sheet_x_under_cap_mm"] = float(np.interp(self.centre[0], self.points[mid, 0] + self.u[mid, 0], self.points[mid, 0]))
        lo, hi = self.layer_z["lattice"]
        b, t = self.plane(lo)[0], self.plane(hi)[0]
        b = b[np.lexsort(self.points[b, :2].T)]
        t = t[np.lexsort(self.points[t, :2].T)]
        out["max_lattice_strain"] = float((self.u[b, 2] - self.u[t, 2]).max() / (hi - lo))
        # the smallest C33 at the lattice's quadrature points (a vertical material line's stretch squared)
        lattice = next(fld for mask, _, fld in self.bodies if self.cell_layer[mask][0] == "lattice")
        F = lattice.extract()[0]
        out["lattice_min_c33"] = float(np.einsum("a...,a...->...", F[:, 2], F[:, 2]).min())
        return out


def cop_x(x_mm: np.ndarray, p_kpa: np.ndarray, w_mm2: np.ndarray) -> float:
    """The force centroid along x of a layer's map (the half-model's is the whole skin's)."""
    f = p_kpa * w_mm2
    return float((x_mm * f).sum() / f.sum())


def run_shear3d(sim, log=print, x_edges=X_EDGES_MM, y_edges=Y_EDGES_MM, depths=SHEAR_FROM_MM, loads_n=LOADS_N,
                partial=None, elements: dict | None = None, cover_nu: float | None = None,
                sticking_press: bool = False) -> dict:
    """Press to each of `depths` (mm), then to each of `loads_n` (the whole skin's F_z, N), and
    from each shear sticking to F_x / F_z = 1/3; `partial(res)` gets the data after each branch.
    res["stopped"] (json) says, per branch, where and why a press or shear stopped short.
    cover_nu: the cover's Poisson ratio (None: the section's, Section.cover_poisson);
    sticking_press: the cap's contact sticks from the first touch (else frictionless while
    pressing, every node in contact stuck where it is at the shear's start)."""
    sec = Section.from_sim(sim)
    if cover_nu is not None:
        sec = dataclasses.replace(sec, cover_nu=cover_nu)
    fe = Stack3D(sec, x_edges=x_edges, y_edges=y_edges, elements=elements)
    log(f"  3D half-model: {len(fe.cells)} hex27, {len(fe.free)} free DOF")
    top = fe.height_mm + sec.radius_mm
    states, stopped = [], {}
    t0 = time.time()
    failures = (RuntimeError, FloatingPointError, np.linalg.LinAlgError)

    def record(phase, it, branch):
        st = fe.state()
        st.update(phase=phase, newton_iterations=it, branch_depth_mm=branch)
        states.append(st)
        log(f"  3D {'press' if phase == 0 else 'shear'} depth {st['depth_mm']:.2f} x {st['cap_x_mm']:.2f}: Fz {st['fz_n']:.4f} "
            f"Fx {st['fx_n']:.4f} N, contact x [{st['contact_from_mm']:.2f}, {st['contact_to_mm']:.2f}], lattice C33 "
            f">= {st['lattice_min_c33']:.3f} ({fe.factorisations} factorisations, {fe.factor_seconds:.0f} s of them, "
            f"{time.time() - t0:.0f} s)")
        return st

    def press_to_load(target: float, start: tuple) -> int:
        """From the press state `start` (Stack3D.snapshot): deeper in PRESS_STEP_MM steps until
        F_z passes target, then the secant in depth until F_z is within LOAD_TOL of it."""
        fe.restore(start)
        total = 0
        lo = (top - fe.centre[2], fe.state()["fz_n"])
        while True:
            total += fe.move_to(np.array([0.0, 0.0, top - lo[0] - PRESS_STEP_MM]), sticking=sticking_press, step_mm=0.1)
            hi = (top - fe.centre[2], fe.state()["fz_n"])
            log(f"  3D press to {target:g} N: depth {hi[0]:.3f} mm, Fz {hi[1]:.4f} N")
            if hi[1] >= target:
                break
            lo, start = hi, fe.snapshot()
        for _ in range(6):
            if abs(hi[1] / target - 1.0) <= LOAD_TOL:
                return total
            d = lo[0] + (target - lo[1]) * (hi[0] - lo[0]) / (hi[1] - lo[1])
            fe.restore(start)  # from the shallower side: the press is monotone
            total += fe.move_to(np.array([0.0, 0.0, top - d]), sticking=sticking_press, step_mm=0.1)
            f = fe.state()["fz_n"]
            if f < target:
                lo, start = (d, f), fe.snapshot()
            else:
                hi = (d, f)
        return total

    # each branch pressed and sheared before the next press: a run cut short keeps whole branches
    press_state = fe.snapshot()
    for target in [("depth", d) for d in depths] + [("load", f) for f in loads_n]:
        name = f"{target[1]:.2f} mm" if target[0] == "depth" else f"{target[1]:g} N"
        try:
            if target[0] == "depth":
                fe.restore(press_state)
                it = fe.move_to(np.array([0.0, 0.0, top - target[1]]), sticking=sticking_press, step_mm=0.1)
            else:
                it = press_to_load(target[1], press_state)
        except failures as err:
            st = fe.state()
            stopped[name] = (f"press stopped at depth {st['depth_mm']:.3f} mm, F_z {st['fz_n']:.4f} N, layer-mean lattice "
                             f"strain {st['max_lattice_strain']:.3f}, smallest lattice C33 {st['lattice_min_c33']:.3f}: {err}")
            log(f"  3D {stopped[name]}")
            break
        press = record(0.0, it, np.nan)
        depth = press["depth_mm"]
        press_state = fe.snapshot()
        c_press = fe.centre.copy()
        if not sticking_press:
            fe.stick_all_in_contact()
        x, st = 0.0, None
        for _ in range(SHEAR_STEPS):
            if st is None:
                x_next = 0.15
            else:
                k = st["fx_n"] / x
                x_next = x + float(np.clip(1.05 * (SHEAR_RATIO * st["fz_n"] - st["fx_n"]) / k, 0.05, 0.5))
            try:
                it = fe.move_to(np.array([x_next, 0.0, c_press[2]]), sticking=True, step_mm=SHEAR_STEP_MM)
            except failures as err:
                # move_to keeps the furthest equilibrium it reached on the way: recorded, so the
                # branch's data end where its equilibrium ends, not at the last planned advance
                if fe.centre[0] > x + 1e-9:
                    x = float(fe.centre[0])
                    st = record(1.0, np.nan, depth)  # its Newton count went with the failure
                stopped[name] = (f"shear stopped at cap travel {x:.3f} mm, F_x / F_z {0 if st is None else st['fx_n'] / st['fz_n']:.3f}"
                                 f" (on the way to {x_next:.3f} mm, the cap's step halved to its floor): {err}")
                log(f"  3D {stopped[name]}")
                break
            x = x_next
            st = record(1.0, it, depth)
            if st["fx_n"] >= SHEAR_RATIO * st["fz_n"]:
                break
        if partial is not None:
            partial({**_pack(fe, states, sec), "stopped": json.dumps(stopped), "sticking_press": np.array(sticking_press)})
    return require_balance3d({**_pack(fe, states, sec), "stopped": json.dumps(stopped),
                              "sticking_press": np.array(sticking_press)}, log)


def scalars(states: list) -> dict:
    """The states' scalar entries (forces, positions, checks) as one array per key."""
    keys = [k for k in states[0] if np.ndim(states[0][k]) == 0]
    return {k: np.array([s[k] for s in states], float) for k in keys}


def _pack(fe: Stack3D, states: list, sec: Section) -> dict:
    out = scalars(states)
    out["contact_nodes_xy"] = fe.points[fe.contact.nodes, :2]
    out["contact_w_mm2"] = fe.contact.weights
    out["contact_kpa"] = np.stack([s["contact_kpa"] for s in states])
    for name, z in fe.line_z().items():
        nodes, w = fe.plane(z)
        out[f"{name}_xy_mm"], out[f"{name}_w_mm2"] = fe.points[nodes, :2], w
        out[f"{name}_kpa"] = np.stack([s[f"{name}_kpa"] for s in states])
        out[f"{name}_shear_kpa"] = np.stack([s[f"{name}_shear_kpa"] for s in states]).astype(np.float32)
        out[f"{name}_normal_kpa"] = np.stack([s[f"{name}_normal_kpa"] for s in states])
        out[f"{name}_u_mm"] = np.stack([s[f"{name}_u_mm"] for s in states]).astype(np.float32)
    out["dof"] = np.array(len(fe.free))
    out["elements"] = json.dumps(fe.elements)
    out["factorisations"] = np.array(fe.factorisations)
    out["factor_seconds"] = np.array(fe.factor_seconds)
    out["section"] = json.dumps(sec.__dict__)
    return out


def balance3d(res: dict) -> dict:
    """Per layer and the cap's contact: 2 sum(p A) / F_z per state (1 when pressures are forces)."""
    out = {}
    faces = tuple(f for f in FACES if f"{f}_kpa" in res)  # data solved before the faces were read lack them
    for line in (*LINES, *faces, "contact"):
        w = res["contact_w_mm2"] if line == "contact" else res[f"{line}_w_mm2"]
        out[line] = 2e-3 * (np.asarray(res[f"{line}_kpa"]) * w).sum(axis=1) / np.asarray(res["fz_n"])
    return out


def moment_balance3d(res: dict) -> dict | None:
    """Per layer: each state's first-moment error of the force through its plane against the
    statics of everything above it (Stack3D.state), over the load's moment (model.moment_scale);
    None for data solved before the states recorded it."""
    if not all(f"{line}_moment_error" in res for line in LINES):
        return None
    return {k.removesuffix("_moment_error"): np.asarray(res[k], float) for k in res if k.endswith("_moment_error")}


def require_balance3d(res: dict, log=print) -> dict:
    worst = {k: float(np.abs(b - 1).max()) for k, b in balance3d(res).items()}
    log(f"  3D balance, worst |2 sum(p A) / F_z - 1| per layer: {worst}")
    if max(worst.values()) > BALANCE_TOL:
        raise RuntimeError(f"a layer's pressure does not carry the load: {worst} (allowed {BALANCE_TOL})")
    return require_moment_balance3d(res, log)


def require_moment_balance3d(res: dict, log=print) -> dict:
    moments = moment_balance3d(res)
    if moments is None:
        log("  3D moment balance: not recorded in these data (solved before the states carried it)")
        return res
    worst_m = {k: float(np.nanmax(np.abs(m))) for k, m in moments.items()}
    log(f"  3D moment balance, worst first-moment error over the load's moment per layer: {worst_m}")
    if max(worst_m.values()) > MOMENT_TOL:
        raise RuntimeError(f"a layer's pressure does not carry the load's moment: {worst_m} (allowed {MOMENT_TOL})")
    return res


def plane_strain_shear(section: dict, res: dict) -> dict:
    """The section (a cylinder, per mm) beside the 3D half-model (the hemisphere, N) per press
    depth: contact half-width, peak superficial and deep pressures, lattice strain at the press;
    at F_x / F_z = 1/3: the superficial and deep force CoPs' travel from the press, the
    inter-layer shift (superficial minus deep CoP), the sheet's shift and the cap's travel.
    'ratio' is 3D / section; 'difference' 3D - section (positions, mm)."""
    sec_cop = {ln: lambda p, ln=ln: float((section[f"{ln}_x_mm"] * p * section[f"{ln}_w_mm"]).sum()
                                          / (p * section[f"{ln}_w_mm"]).sum()) for ln in ("superficial", "deep")}
    cop3 = {ln: lambda p, ln=ln: cop_x(res[f"{ln}_xy_mm"][:, 0], p, res[f"{ln}_w_mm2"]) for ln in ("superficial", "deep")}
    rows = {}
    for depth in SHEAR_FROM_MM:
        a = at_ratio(section, "fz_n_per_mm", "fx_n_per_mm", depth,
                      ("cap_x_mm", "superficial_kpa", "deep_kpa", "sheet_shift_mm"))
        b = at_ratio(res, "fz_n", "fx_n", depth, ("cap_x_mm", "superficial_kpa", "deep_kpa", "sheet_shift_mm"))
        i = np.flatnonzero((section["phase"] == 0) & np.isclose(section["depth_mm"], depth))
        j = np.flatnonzero((res["phase"] == 0) & np.isclose(res["depth_mm"], depth))
        if len(i) == 0 or len(j) == 0:
            continue
        i, j = int(i[0]), int(j[0])
        ratios = {
            "contact_half_width_mm": (0.5 * (section["contact_to_mm"][i] - section["contact_from_mm"][i]),
                                      0.5 * (res["contact_to_mm"][j] - res["contact_from_mm"][j])),
            "peak_superficial_kpa": (section["superficial_kpa"][i].max(), res["superficial_kpa"][j].max()),
            "peak_deep_kpa": (section["deep_kpa"][i].max(), res["deep_kpa"][j].max()),
            "max_lattice_strain": (section["max_lattice_strain"][i], res["max_lattice_strain"][j]),
        }
        row = {k: {"section": round(float(u), 5), "3d": round(float(v), 5), "ratio": round(float(v / u), 4)}
               for k, (u, v) in ratios.items()}
        row["load"] = {"section_n_per_mm": round(float(section["fz_n_per_mm"][i]), 5), "3d_n": round(float(res["fz_n"][j]), 5)}
        if a is None or b is None:
            row["shear"] = "not reached: " + ("section" if a is None else "3D") + " branch stopped below F_x / F_z = 1/3"
        else:
            def shear_side(s, cop, press):
                sup = cop["superficial"](s["superficial_kpa"]) - cop["superficial"](press["superficial"])
                deep = cop["deep"](s["deep_kpa"]) - cop["deep"](press["deep"])
                return {"cap_travel_mm": float(s["cap_x_mm"]), "superficial_cop_travel_mm": sup, "deep_cop_travel_mm": deep,
                        "interlayer_shift_mm": cop["superficial"](s["superficial_kpa"]) - cop["deep"](s["deep_kpa"]),
                        "sheet_shift_mm": float(s["sheet_shift_mm"])}
            sa = shear_side(a, sec_cop, {"superficial": section["superficial_kpa"][i], "deep": section["deep_kpa"][i]})
            sb = shear_side(b, cop3, {"superficial": res["superficial_kpa"][j], "deep": res["deep_kpa"][j]})
            row["shear"] = {k: {"section": round(sa[k], 5), "3d": round(sb[k], 5), "difference": round(sb[k] - sa[k], 5)}
                            for k in sa}
        rows[f"{depth:.2f} mm"] = row
    return rows


# what the 3D check reads through the taxel grid (alignment.fem3d_signals), beside the section
COUNT_SIGNALS = ("superficial_cop_counts_mm", "deep_cop_counts_mm", "interlayer_shift_counts_mm",
                 "superficial_offset_counts_mm", "effective_height_counts", "superficial_asymmetry_counts")


def count_signals_vs_section(res: dict, sim, data: Path = DATA) -> dict:
    """The count-CoP shear signals of the 3D half-model beside the section's, per branch depth,
    each read through the simulator's FSR law and readout (compare.Reader) and averaged over the
    taxel grid's alignments (alignment.ALIGN_TAXEL_MM; the 3D model along x and across, the
    section along x, its cells also over its wall alignments). 'plane_strain_error' is the 3D
    mean minus the homogenised section's without the solid rim (homogenised_no_rim.npz: the same
    lattice model out to the pad's sides, so plane strain and the 3D mesh); '3d_minus_cells' the
    3D mean minus the section with cells (plane strain, homogenisation and the rim together). Positions in mm; the effective height -F_z dc / F_x in mm too."""
    from layerskin_exp.sim.fem_reference.alignment import (
        ALIGN_TAXEL_MM,
        _summary,
        fem3d_signals,
        section_signals,
    )

    sec = section_signals(sim, data, homogenised="homogenised_no_rim")  # the 3D model has no solid rim
    three: dict = {}
    for tx in ALIGN_TAXEL_MM:
        for ty in ALIGN_TAXEL_MM:
            for b, sig in fem3d_signals(res, sec["model"], tx, ty).items():
                three.setdefault(b, []).append(sig)

    def at(by: dict, depth: float):
        return next((v for b, v in by.items() if np.isclose(b, depth)), None)

    rows = {}
    for depth in sorted(set(SHEAR_FROM_MM) | set(three)):
        t, h, c = at(three, depth), at(sec["homogenised"], depth), at(sec["cells"], depth)
        if t is not None and h is None and c is None:  # a load the section was not sheared at
            rows[f"{depth:.2f} mm"] = {"load": {"3d_n": t[0]["fz_n"]},
                                       **{name: {"3d": _summary([r[name] for r in t])} for name in COUNT_SIGNALS}}
            continue
        if t is None or h is None or c is None:
            rows[f"{depth:.2f} mm"] = "not reached: " + ", ".join(
                n for n, v in (("3D", t), ("homogenised section", h), ("section", c)) if v is None) + \
                " stopped below F_x / F_z = 1/3"
            continue
        row = {"load": {"3d_n": t[0]["fz_n"], "section_n_per_mm": c[0]["fz_n_per_mm"]}}
        for name in COUNT_SIGNALS:
            st, sh, sc = (_summary([r[name] for r in v]) for v in (t, h, c))
            row[name] = {"3d": st, "section_homogenised": sh, "section_cells": sc,
                         "plane_strain_error": st["mean"] - sh["mean"], "3d_minus_cells": st["mean"] - sc["mean"]}
        rows[f"{depth:.2f} mm"] = row
    return rows


# 3D quantities judged by their change in mm between the meshes (the others relatively)
POSITIONS3D = ("cap_travel_mm", "superficial_cop_travel_mm", "deep_cop_travel_mm", "interlayer_shift_mm", "sheet_shift_mm",
               "superficial_cop_counts_mm", "deep_cop_counts_mm", "interlayer_shift_counts_mm",
               "superficial_offset_counts_mm")


def quantities3d(res: dict, sim, depth: float = REFINEMENT_DEPTH_MM, data: Path = DATA) -> dict:
    """Every quantity the 3D check reports for the branch pressed to `depth`: the press's (contact
    half-width, peak pressures, lattice strain, F_z), the force CoPs' at F_x / F_z = 1/3 and the
    count signals' means over the taxel grid's alignments; the same functions as shear3d.json's."""
    section = dict(np.load(data / "bonded.npz"))
    label = f"{depth:.2f} mm"
    row = plane_strain_shear(section, res)[label]
    out = {k: v["3d"] for k, v in row.items() if isinstance(v, dict) and "3d" in v}
    out["fz_n"] = row["load"]["3d_n"]
    if isinstance(row.get("shear"), dict):
        out.update({k: v["3d"] for k, v in row["shear"].items()})
    counts = count_signals_vs_section(res, sim, data).get(label)
    if isinstance(counts, dict):
        out.update({k: counts[k]["3d"]["mean"] for k in COUNT_SIGNALS})
    return out


def refinement3d(coarse: dict, fine: dict, sim, depth: float = REFINEMENT_DEPTH_MM, data: Path = DATA) -> dict:
    """Each 3D quantity on the committed mesh and on the refined one, and its change: relative,
    or in mm for POSITIONS3D; converged as the section's are (convergence.REL_TOL / POS_TOL_MM)."""
    from layerskin_exp.sim.fem_reference.convergence import POS_TOL_MM, REL_TOL, judge

    a, b = quantities3d(coarse, sim, depth, data), quantities3d(fine, sim, depth, data)
    rows = {name: {"committed": round(float(a[name]), 6), "refined": round(float(b[name]), 6),
                   **judge(a[name], b[name], name in POSITIONS3D)} for name in a if name in b}
    return {"depth_mm": depth, "committed_dof": int(coarse["dof"]), "refined_dof": int(fine["dof"]),
            "rel_tol": REL_TOL, "pos_tol_mm": POS_TOL_MM, "quantities": rows}


def through_thickness3d(committed: dict, by_name: dict, sim, depth: float = REFINEMENT_DEPTH_MM,
                        data: Path = DATA) -> dict:
    """Each step of THROUGH_THICKNESS_STEPS (from the committed mesh's branch, or from one of
    `by_name`'s, THROUGH_THICKNESS's runs, to another), judged as `refinement3d` judges a step."""
    def run(name):
        return committed if name is None else by_name[name]

    return {"depth_mm": depth, "committed_elements": STACK_ELEMENTS, "runs": THROUGH_THICKNESS,
            "steps": {step: {**refinement3d(run(a), run(b), sim, depth, data), "from": a, "to": b}
                      for step, (a, b) in THROUGH_THICKNESS_STEPS.items()}}


def mesh_error3d(conv: dict, through: dict | None = None) -> dict:
    """Each 3D quantity's mesh error on the committed mesh: its change under the in-plane
    refinement (`conv`, shear3d_convergence.json) plus its change in each through-thickness step
    from the committed mesh (`through`, shear3d_through_thickness.json); converged where every
    one of those changes is."""
    steps = [] if through is None else [st for st in through["steps"].values() if st.get("from") is None]
    out = {}
    for name, q in conv["quantities"].items():
        more = [st["quantities"][name] for st in steps if name in st["quantities"]]
        out[name] = {"change": abs(q["change"]) + sum(abs(t["change"]) for t in more),
                     "converged": q["converged"] and all(t["converged"] for t in more)}
    return out


def uncovered3d(conv: dict, tolerances: dict, through: dict | None = None) -> list[str]:
    """3D quantities whose mesh error (mesh_error3d) is neither converged nor recorded:
    tolerances.yaml's `plane_strain_mesh:` gives each plane-strain figure's own mesh error
    (relative, or mm for POSITIONS3D), which must be at least the measured one."""
    recorded = tolerances.get("plane_strain_mesh", {}) or {}
    return [name for name, q in mesh_error3d(conv, through).items()
            if not q["converged"] and not q["change"] <= recorded.get(name, -1.0)]


# The branch at the study's load (`--shear3d-load-branch`): what carries the cap's tangential load
# at 3 N. The committed run's 3 N branch stops at F_x / F_z = 0.005 (its cover gives up its volume,
# module docstring); this one is pressed with a cover that keeps it (nu 0.499), sticking from the
# first touch (the simulator's cover friction is 1), on the refined mesh (the coarse one's contact
# is one ring of nodes wide), and sheared sticking as far as Newton goes.
LOAD_BRANCH = {"loads_n": (3.0,), "cover_nu": 0.499, "sticking_press": True,
               "x_edges": REFINED_X_EDGES_MM, "y_edges": REFINED_Y_EDGES_MM}
# The branch between the two (`--shear3d-mid-branch`), the load branch's recipe at 0.83 N: with the
# sheet's bending stiffness the crossed laminate's, the frictionless press on the committed mesh no
# longer passes 0.4 mm (Newton stalls at |r| ~ 1e-3 of the load however small the step, the cover's
# nodes at the contact's edge flipping in and out of contact).
MID_BRANCH = {**LOAD_BRANCH, "loads_n": (0.83,)}


# The stiff end of the cover's bracket (the study says only "a 0.2 mm silicone cover"): 35 kPa, the
# spacer's own silicone (nominal), to 1 MPa, a Dragon Skin / Sil-Poxy class. The yardstick's second
# design is the load branch with this cover.
STIFF_COVER_KPA = 1000.0


def stiff_cover_sim(sim):
    """The design with the stiff end of the cover's bracket."""
    return dataclasses.replace(sim, cover=dataclasses.replace(sim.cover, modulus_kpa=STIFF_COVER_KPA))


def series_shear_stiffness(sec: Section, a_x_mm: float, a_y_mm: float) -> dict:
    """The cap's tangential stiffness while sticking, as two springs in series (N/mm): the cover's
    shear under the contact patch, G_c pi a_x a_y / t_c (the cover outside the patch and the sheets'
    shear left out), and the lattice's transverse shear over the whole pad under the membrane-stiff
    sheet, G13 A / h (Gibson & Ashby's G13 = rho G_s / 2)."""
    g_cover = sec.cover_e_mpa / (2.0 * (1.0 + sec.cover_poisson()))
    k_cover = g_cover * np.pi * a_x_mm * a_y_mm / sec.cover_mm
    k_lattice = sec.honeycomb_moduli_kpa()[1] * KPA * sec.width_mm ** 2 / sec.lattice_mm
    return {"cover_n_per_mm": k_cover, "lattice_n_per_mm": k_lattice,
            "series_n_per_mm": 1.0 / (1.0 / k_cover + 1.0 / k_lattice)}


def thin_layer_half_width_mm(sec: Section, load_n: float) -> float:
    """The contact radius of a rigid sphere (the cap's radius R) pressed by load_n into a thin
    incompressible layer (the cover, thickness t, shear modulus G) bonded to a rigid backing and
    stuck to the sphere: the layer's squeeze flow between two no-slip faces, (t^3 / 12 G) lap(p) =
    -(delta - r^2 / 2R), with p = p' = 0 at the contact's edge, gives p = 12 G (a^2 - r^2)^2 /
    (32 R t^3) and P = pi G a^6 / (8 R t^3) (derived here: the incompressible counterpart of the
    thin compressible layer of Johnson 1985, sec. 5.9, which tests/sim/test_fem_closed_forms.py
    checks; valid for a >> t, and it leaves out the backing's own deflection)."""
    g_cover = sec.cover_e_mpa / (2.0 * (1.0 + sec.cover_poisson()))
    return float((8.0 * load_n * sec.radius_mm * sec.cover_mm ** 3 / (np.pi * g_cover)) ** (1.0 / 6.0))


def load_branch3d(res: dict) -> dict:
    """Per load branch of `res`: the press (F_z, depth, contact patch), each sheared state's secant
    stiffness F_x / travel and the sheet's share of the travel beside the series closed form, and
    what the closed form says the branch needs to reach F_x / F_z = 1/3: the cap's travel and the
    cover's mean shear strain under the patch ((travel - sheet travel) / t_c)."""
    sec = Section(**json.loads(str(res["section"])))
    out = {}
    for j in np.flatnonzero(res["phase"] == 0):
        depth = float(res["depth_mm"][j])
        a_x = 0.5 * float(res["contact_to_mm"][j] - res["contact_from_mm"][j])
        a_y = float(res["contact_y_mm"][j])
        k = series_shear_stiffness(sec, a_x, a_y)
        idx = np.flatnonzero((res["phase"] == 1) & np.isclose(res["branch_depth_mm"], depth))
        fz = float(res["fz_n"][j])
        travel = fz * SHEAR_RATIO / k["series_n_per_mm"]
        a_thin = thin_layer_half_width_mm(sec, fz)
        k_thin = series_shear_stiffness(sec, a_thin, a_thin)
        out[f"{fz:.2f} N"] = {
            "press": {"depth_mm": depth, "fz_n": fz, "contact_half_width_x_mm": a_x, "contact_half_width_y_mm": a_y},
            "closed_form": {**k, "sheet_share": k["series_n_per_mm"] / k["lattice_n_per_mm"],
                            "travel_to_ratio_mm": travel,
                            "cover_shear_strain_at_ratio": fz * SHEAR_RATIO / k["cover_n_per_mm"] / sec.cover_mm},
            # the same with the patch from the thin-layer closed form instead of the mesh's
            "thin_layer": {"contact_half_width_mm": a_thin, **k_thin,
                           "travel_to_ratio_mm": fz * SHEAR_RATIO / k_thin["series_n_per_mm"],
                           "cover_shear_strain_at_ratio": fz * SHEAR_RATIO / k_thin["cover_n_per_mm"] / sec.cover_mm},
            "sheared": [{"cap_travel_mm": float(res["cap_x_mm"][i]), "fz_n": float(res["fz_n"][i]),
                         "fx_n": float(res["fx_n"][i]), "ratio": float(res["fx_n"][i] / res["fz_n"][i]),
                         "stiffness_n_per_mm": float(res["fx_n"][i] / res["cap_x_mm"][i]),
                         "stiffness_over_closed_form": float(res["fx_n"][i] / res["cap_x_mm"][i] / k["series_n_per_mm"]),
                         "sheet_share": float(res["sheet_shift_mm"][i] / res["cap_x_mm"][i])} for i in idx],
        }
    return out


def fast_at_load_branch(sim, res: dict, model_hook=None) -> dict:
    """The fast model beside each load branch of `res` (shear3d_load_branch.npz): the hemisphere
    of the cap's radius, the section's bound and readout (compare.line_sim; model_hook(sim) -> sim
    alters its design), pressed to the branch's F_z and moved sticking by the branch's first
    travel. {branch: {quantity: (3D, fast)}}: F_z at the 3D's depth, contact half-width, the secant
    tangential stiffness over that travel and the sheet's share of it."""
    from layerskin_exp import rig
    from layerskin_exp.sim.fem_reference.compare import SKIN, line_sim
    from layerskin_exp.sim.mechanics import S_FX, S_FZ, S_UX
    from layerskin_exp.sim.skin import SkinModel

    fsim = line_sim(sim, "bonded")
    model = SkinModel(fsim if model_hook is None else model_hook(fsim), SKIN, "hemisphere", np.random.default_rng(0),
                      contact_radius_mm=rig.INDENTER_RADIUS_MM)
    tab, fresh = model.tab, model.mech_state()
    out = {}
    for j in np.flatnonzero(res["phase"] == 0):
        depth, fz = float(res["depth_mm"][j]), float(res["fz_n"][j])
        i = int(np.flatnonzero((res["phase"] == 1) & np.isclose(res["branch_depth_mm"], depth))[0])
        travel = float(res["cap_x_mm"][i])
        delta = float(np.interp(fz, tab.load, tab.delta_mm))
        model.restore_mech_state(fresh)
        model.step_many(np.array([0.0]), np.array([[0.0, 0.0, -delta]]), np.array([0.0]))
        xs = np.linspace(0.0, travel, 31)[1:]
        rec = model.step_many(1e-3 * np.arange(1, len(xs) + 1), np.column_stack([xs, 0 * xs, -delta + 0 * xs]),
                              np.zeros(len(xs)))[-1]
        out[f"{fz:.2f} N"] = {
            "load_at_depth_n": (fz, float(np.interp(depth, tab.delta_mm, tab.load))),
            "contact_half_width_mm": (0.5 * float(res["contact_to_mm"][j] - res["contact_from_mm"][j]),
                                      float(np.interp(delta, tab.delta_mm, tab.contact_halfwidth_mm))),
            "tangential_stiffness_n_per_mm": (float(res["fx_n"][i]) / travel, float(rec[S_FX]) / travel),
            "sheet_share_of_travel": (float(res["sheet_shift_mm"][i]) / travel, float(rec[S_UX]) / travel),
            "fast_fz_n": float(rec[S_FZ]),
        }
    return out


# each load-branch quantity judged and the tolerances' metric whose band judges it (the contact
# half-width is in fast_at_load_branch's record only: no injected error of the fast model moves it
# out of the contact_width band at 3 N, so as a check it could not be shown to fail)
LOAD_BRANCH_METRICS = {"load_at_depth_n": "line_load_at_depth", "tangential_stiffness_n_per_mm": "tangential_stiffness",
                       "sheet_share_of_travel": "sheet_share_of_travel"}


def load_branch_rows(sim, tolerances: dict, data: Path = DATA, model_hook=None) -> list:
    """The fast model against the 3D check at the study's load (shear3d_load_branch.npz), one
    Comparison per quantity of fast_at_load_branch, each in the band of the tolerances' metric that
    judges the same physics in the section (LOAD_BRANCH_METRICS). Not in validate's gate yet: a
    reference is a yardstick once its figures converge, and this branch's mesh error (the same
    branch on a finer mesh, ~4x the refined mesh's cost per factorisation) is not measured; the
    refined mesh's patch is 0.82 of the thin-layer closed form's radius. Printed by
    `--shear3d-load-branch`."""
    from layerskin_exp.sim.fem_reference.compare import Comparison

    res = dict(np.load(data / "shear3d_load_branch.npz"))
    rows = []
    for b, row in fast_at_load_branch(sim, res, model_hook).items():
        for name, metric in LOAD_BRANCH_METRICS.items():
            fem_value, fast_value = row[name]
            if metric in tolerances["ratio"]:
                kind, (lo, hi) = "ratio", tolerances["ratio"][metric]
            else:
                kind, lo, hi = "difference", -tolerances["difference"][metric], tolerances["difference"][metric]
            rows.append(Comparison("3D", metric, f"{b}, hemisphere", fem_value, fast_value, kind, lo, hi))
    return rows


def _sheet_squeeze(fe: Stack3D, u0: np.ndarray, u: np.ndarray) -> dict:
    """The films' squeeze of the superficial core, from the sheet's own deflection at a state `u`
    (its press `u0`), and the first moments it puts on the mid-plane.

    A bonded sheet carries its bending moment M as a membrane couple, -+ M / d in its upper and
    lower half (d the lever between them); a membrane force along the curved sheet presses on what
    lies under or over it, so the mid-plane reads the faces' mean plus -div(M grad w) / d (w
    positive down, M = D [(1 - nu) kappa + nu tr(kappa) I], kappa = -grad grad w). For the merged
    sheet D is its bending rigidity and d = 2t / 3, the lever between its half-thickness stress
    blocks (a film/core/film laminate's is the films' separation, 0.143 mm against 0.124 here).
    By the divergence theorem the squeeze's first moment about x is int (M grad w)_x dA / d.
    It is the z component's excess: div(M grad w) = M : grad grad w + div(M) . grad w, a squeeze
    along the curvature and the sheet's transverse shear force Q = div(M) tilted by the slope, which
    a reading along the sheet's normal does not have (`Stack3D.plane_normals`; at 0.3 mm the normal
    reading of the mid-plane trails the faces' mean, so the curvature term alone does not describe
    the merged sheet either).
    Finite differences on the mid-plane's node grid, mirrored across y = 0. Returns that moment
    (N mm, the half-model's) from the cross terms of the press's and the shear's deflections
    (the press's own term has none by symmetry), the same with the press's moment against the
    shear deflection's best-fitting tilt across the pad alone, and that tilt's slope."""
    sec = fe.sec
    t = 2 * sec.film_mm + sec.core_mm
    nu = 0.34
    rigidity = merged_sheet_e_mpa(sec) * t ** 3 / (12 * (1 - nu ** 2))
    lever = 2.0 * t / 3.0
    nodes = fe.plane(fe.line_z()["superficial"])[0]
    xs, ix = np.unique(np.round(fe.points[nodes, 0], 9), return_inverse=True)
    ys, iy = np.unique(np.round(fe.points[nodes, 1], 9), return_inverse=True)
    yy = np.concatenate([-ys[:0:-1], ys])

    def grid(v):
        g = np.zeros((len(xs), len(ys)))
        g[ix, iy] = v
        return np.concatenate([g[:, :0:-1], g], axis=1)

    def moment_and_slope(W):  # (second-order at the grid's ends too: exact for a quadratic field)
        wx, wy = np.gradient(W, xs, yy, edge_order=2)
        wxx, wxy = np.gradient(wx, xs, yy, edge_order=2)
        wyy = np.gradient(wy, yy, axis=1, edge_order=2)
        m = (rigidity * (-wxx - nu * wyy), rigidity * (-wyy - nu * wxx), rigidity * (1 - nu) * -wxy)
        return m, (wx, wy)

    def trapezoid(v):  # each node's share of its line (half an interval at the ends)
        share = np.gradient(v)
        share[0], share[-1] = 0.5 * (v[1] - v[0]), 0.5 * (v[-1] - v[-2])
        return share

    area = np.outer(trapezoid(xs), trapezoid(yy))

    def first(m, g):  # int (M grad w)_x dA / d over the half (the divergence theorem's moment)
        return 0.5 * float(((m[0] * g[0] + m[2] * g[1]) * area).sum()) / lever

    w_press, w_now = grid(-u0[nodes, 2]), grid(-u[nodes, 2])
    shear = w_now - w_press
    m0, g0 = moment_and_slope(w_press)
    m1, g1 = moment_and_slope(shear)
    # the best-fitting tilt w = slope x: its gradient is (slope, 0) everywhere, its moment nil
    slope = float((shear * xs[:, None] * area).sum() / (xs[:, None] ** 2 * area).sum())
    gt = (np.full_like(shear, slope), np.zeros_like(shear))
    return {"cross_terms": first(m0, g1) + first(m1, g0) + first(m1, g1), "tilt_term": first(m0, gt),
            "tilt_slope": slope}


# the squeeze study's branches (`squeeze3d`): press depth (mm) -> cap travels (mm), the last near where
# the committed run's branch reaches F_t / F_z = 1/3 (0.545 mm; the 0.6 mm frictionless press no longer
# converges, MID_BRANCH)
SQUEEZE_BRANCHES = {0.3: (0.3, 0.545)}


def squeeze3d(sim, branches: dict = SQUEEZE_BRANCHES, log=print) -> dict:
    """`squeeze_branch3d` for each press depth of `branches` (its cap travels)."""
    return {"branches": [squeeze_branch3d(sim, depth, travels, log) for depth, travels in branches.items()]}


def squeeze_branch3d(sim, depth: float, travels, log=print) -> dict:
    """The 3D model's mid-plane reading against its faces' mean and the films' squeeze: the
    committed mesh pressed to `depth` (frictionless) and sheared sticking to each of `travels`
    (mm of cap travel); per state the force CoP (sheet's frame, x) of the mid-plane, of the faces'
    mean and of that mean plus the squeeze's first moment (`_sheet_squeeze`), and the share of the
    squeeze's moment that the sheet's tilt across the pad gives; beside them the mid-plane's and
    the faces' mean read along the sheet's normal (what the FSR reads, `Stack3D.plane_normals`)."""
    sec = Section.from_sim(sim)
    fe = Stack3D(sec, x_edges=X_EDGES_MM, y_edges=Y_EDGES_MM)
    top = fe.height_mm + sec.radius_mm
    # the committed run's path (run_shear3d): pressed through the shallower branches' depths, then
    # sheared through its first advance (Newton's contact sets depend on the path)
    for d in [d for d in SHEAR_FROM_MM if d < depth] + [depth]:
        fe.move_to(np.array([0.0, 0.0, top - d]), sticking=False, step_mm=0.1)
    u0, centre = fe.u.copy(), fe.centre.copy()
    fe.stick_all_in_contact()
    lines = fe.line_z()
    # a rigid pad rocking on the lattice (E3 / h per area, the square pad's second moment L^4 / 12)
    rocking = sec.honeycomb_moduli_kpa()[0] * KPA / sec.lattice_mm * sec.width_mm ** 4 / 12.0
    out = {"depth_mm": depth, "states": []}
    for travel in travels:
        if fe.centre[0] < 0.15 < travel:
            fe.move_to(np.array([0.15, 0.0, centre[2]]), sticking=True, step_mm=SHEAR_STEP_MM)
        fe.move_to(np.array([travel, 0.0, centre[2]]), sticking=True, step_mm=SHEAR_STEP_MM)
        st = fe.state()
        maps = {k: fe.transmitted(lines[k]) for k in ("superficial", "sheet_top", "sheet_bottom")}
        x = fe.points[maps["superficial"][0], 0]
        fz_half = float(maps["superficial"][2][:, 2].sum())

        def cop(g, x=x):
            return float((x * g).sum() / g.sum())

        mid = maps["superficial"][2][:, 2]
        faces = 0.5 * (maps["sheet_top"][2][:, 2] + maps["sheet_bottom"][2][:, 2])
        normal = {k: (maps[k][2] * fe.plane_normals(maps[k][0])).sum(axis=1) for k in maps}
        sq = _sheet_squeeze(fe, u0, fe.u)
        row = {"cap_travel_mm": travel, "fz_n": st["fz_n"], "fx_n": st["fx_n"], "cop_mid_plane_mm": cop(mid),
               "cop_faces_mean_mm": cop(faces), "cop_mid_plane_normal_mm": cop(normal["superficial"]),
               "cop_faces_mean_normal_mm": cop(0.5 * (normal["sheet_top"] + normal["sheet_bottom"])),
               "mid_plane_excess_mm": float((x * (mid - faces)).sum()) / fz_half,
               "squeeze_closed_form_mm": sq["cross_terms"] / fz_half,
               "squeeze_from_tilt_mm": sq["tilt_term"] / fz_half, "sheet_tilt_slope": sq["tilt_slope"]}
        row["cop_faces_mean_plus_squeeze_mm"] = row["cop_faces_mean_mm"] + row["squeeze_closed_form_mm"]
        # under the load's moment about the pad's centre at the deep plane
        moment = st["fz_n"] * st["load_x_mm"] + st["fx_n"] * (st["load_height_mm"] - lines["deep"])
        row["rigid_rocking_slope"] = moment / rocking
        log(f"  3D squeeze at travel {travel:.3f} mm: " + ", ".join(f"{n} {v:.4g}" for n, v in row.items()))
        out["states"].append(row)
    return out


# The diagonal branch (`--shear3d-diagonal`): the whole pad (no symmetry plane), the committed
# mesh's edges in x and mirrored in y (the same edges, so the mesh is symmetric about the pad's
# diagonal), pressed to DIAGONAL_DEPTH_MM and sheared sticking by DIAGONAL_TRAVEL_MM along x and
# along the diagonal (each from the same press). The homogenised lattice is transversely isotropic,
# so the two must answer alike up to the square pad's shape; judged within DIAGONAL_TOL (relative,
# forces) and DIAGONAL_POS_TOL_MM (travels), fixed before the branch was first solved.
DIAGONAL_DEPTH_MM = SHEAR_FROM_MM[0]
DIAGONAL_TRAVEL_MM = 0.545  # where the half-model's 0.3 mm branch reaches F_x / F_z = 1/3
DIAGONAL_TOL = 0.05
DIAGONAL_POS_TOL_MM = 0.1


def diagonal3d(sim, depth: float = DIAGONAL_DEPTH_MM, travel: float = DIAGONAL_TRAVEL_MM, log=print) -> dict:
    """Along x and along the diagonal, from one press: the tangential force along and across the
    shear, F_z, each layer's force-CoP travel from the press (the sheet's frame) and the sheet's
    travel under the cap, along and across; each layer's balance 2 sum(p A) / F_z (here sum)."""
    sec = Section.from_sim(sim)
    y_edges = tuple(sorted({-y for y in Y_EDGES_MM} | set(Y_EDGES_MM)))
    fe = Stack3D(sec, x_edges=X_EDGES_MM, y_edges=y_edges, symmetric=False)
    log(f"  3D whole pad: {len(fe.cells)} hex27, {len(fe.free)} free DOF")
    top = fe.height_mm + sec.radius_mm
    t0 = time.time()
    fe.move_to(np.array([0.0, 0.0, top - depth]), sticking=False, step_mm=0.1)
    press, centre = fe.snapshot(), fe.centre.copy()
    lines = {k: fe.line_z()[k] for k in ("superficial", "deep")}

    def read() -> dict:
        c = fe.contact
        f = c.forces(fe.points[c.nodes] + fe.u[c.nodes], fe.centre)[0]  # (not the whole tangent: _system)
        force = -f.sum(axis=0)  # on the skin: F_z > 0 compressive, the tangential along the cap's motion
        force[:2] *= -1.0
        out = {"f_n": force.tolist()}
        for name, z in lines.items():
            nodes, _, g = fe.transmitted(z)
            xy = fe.points[nodes, :2]
            out[f"{name}_cop_mm"] = ((xy * g[:, 2:3]).sum(axis=0) / g[:, 2].sum()).tolist()
            out[f"{name}_balance"] = float(g[:, 2].sum() / force[2])
        sheet = fe.plane(lines["superficial"])[0]
        near = sheet[np.hypot(*fe.points[sheet, :2].T) < 1.0]
        out["sheet_travel_mm"] = fe.u[near, :2].mean(axis=0).tolist()
        return out

    at_press = read()
    log(f"  3D whole pad pressed to {depth} mm: F {np.round(at_press['f_n'], 4)} ({time.time() - t0:.0f} s)")
    branches = {}
    for name, angle in (("along x", 0.0), ("diagonal", 45.0)):
        fe.restore(press)
        fe.stick_all_in_contact()
        e = np.array([np.cos(np.radians(angle)), np.sin(np.radians(angle))])
        for d in (0.15, travel):
            fe.move_to(centre + np.array([*(d * e), 0.0]), sticking=True, step_mm=SHEAR_STEP_MM)
        st = read()
        across = np.array([-e[1], e[0]])

        def split(v, at_press_v=None, e=e, across=across):
            v = np.asarray(v) - (0.0 if at_press_v is None else np.asarray(at_press_v))
            return {"along": float(v @ e), "across": float(v @ across)}

        branches[name] = {"angle_deg": angle, "travel_mm": travel, "fz_n": st["f_n"][2],
                          "ft_n": split(st["f_n"][:2]),
                          "superficial_cop_travel_mm": split(st["superficial_cop_mm"], at_press["superficial_cop_mm"]),
                          "deep_cop_travel_mm": split(st["deep_cop_mm"], at_press["deep_cop_mm"]),
                          "sheet_travel_mm": split(st["sheet_travel_mm"]),
                          "balance": {k: st[f"{k}_balance"] for k in lines}}
        b = branches[name]
        log(f"  3D whole pad sheared {name}: F_t {b['ft_n']}, F_z {b['fz_n']:.4f}, superficial CoP "
            f"{b['superficial_cop_travel_mm']}, deep {b['deep_cop_travel_mm']}, sheet {b['sheet_travel_mm']} "
            f"({time.time() - t0:.0f} s)")
    a, d = branches["along x"], branches["diagonal"]
    diff = {"ft_relative": d["ft_n"]["along"] / a["ft_n"]["along"] - 1.0,
            "fz_relative": d["fz_n"] / a["fz_n"] - 1.0,
            **{k: d[k]["along"] - a[k]["along"] for k in ("superficial_cop_travel_mm", "deep_cop_travel_mm",
                                                          "sheet_travel_mm")}}
    return {"depth_mm": depth, "dof": int(len(fe.free)), "press": at_press, "branches": branches,
            "diagonal_minus_x": diff, "tol": DIAGONAL_TOL, "pos_tol_mm": DIAGONAL_POS_TOL_MM}
