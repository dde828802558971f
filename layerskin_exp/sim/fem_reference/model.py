"""A plane-strain finite-element section of the two-layer skin under a rigid cylindrical cap
(felupe: finite-strain hyperelasticity, bi-quadratic quads).

What is modelled, from the base up (lengths mm, stresses MPa = N/mm^2, forces N per mm of
section depth):
- the base: rigid; the lattice is bonded to it (the deep FSR sheet lies on it and only reads
  the walls' pressure, so its own deformation is left out);
- the lattice spacer as cells: the walls crossing the section (two thirds of a hexagonal
  honeycomb's wall material) as vertical silicone walls at the cell pitch; the walls lying
  along it (the other third) smeared over the voids as a compressible medium that carries the
  honeycomb's transverse shear G rho / 2 and whose energy grows without bound as a cell is
  squeezed flat (it carries the walls' contact when a cell closes, like a third medium:
  Wriggers, Schroder & Auricchio 2013). Without it a plane-strain section shears only by
  bending its crossing walls, some 25 times softer than a honeycomb;
- the superficial FSR sheet as its three layers: the film whose copper strips run along the
  section (polyimide + copper, homogenised), the Velostat core, the film whose strips cross
  the section (strips and polyimide gaps in series); between films and core either the same
  material (bonded bound) or a 5 um layer that transmits pressure but hardly any shear
  (frictionless bound: nearly incompressible, shear modulus 1e-7 of the core's);
- the 0.2 mm silicone cover;
- the rigid cap, a cylinder of the hemisphere's radius (the section's indenter), pressed by
  penalty contact: frictionless while it presses in, sticking (no slip) during the shear
  phase, with nodes that come into contact while shearing stuck where they touch and nodes
  whose contact force turns tensile released.

Nothing of the fast model's contact law, plate theory, couple response or shear stiffness is
used: each layer's pressure, the flank load, the cover's shear and the cells' deformation come
out of the continuum solution.

What the section misses (state it beside every comparison): it is a line contact, infinite
along the cap's axis (forces are per mm; a hemisphere's load spreads in two directions, a
cylinder's in one); the walls are plane-strain plates, stiffer against buckling than a
honeycomb's short walls; the crossing film's strips are homogenised; the deep sheet's
bending and the bottom film are left out (the base is rigid); the air in closed cells is
ignored.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import felupe as fem
import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import spsolve

from layerskin_exp import rig
from layerskin_exp.sim.config import SimConfig

KPA = 1e-3  # MPa per kPa
# A regular hexagonal honeycomb has its walls in three directions. Cut along one of them, two
# thirds of the wall material crosses the section (the walls at +-60 deg, drawn as bands) and one
# third lies along it (the walls parallel to the section, which carry shear along x by their
# in-plane stiffness and which a plane-strain section can only smear over the voids).
BAND_SHARE = 2.0 / 3.0


@dataclass(frozen=True)
class Section:
    """Geometry and materials of the section, from the simulator's configuration (the same
    material data the fast model starts from, nothing fitted)."""

    width_mm: float
    lattice_mm: float
    pitch_mm: float
    wall_mm: float  # width of the section's walls (those crossing it)
    solid_fraction: float  # the honeycomb's, in plan
    cover_mm: float
    film_mm: float
    core_mm: float
    slip_mm: float
    silicone_e_mpa: float
    silicone_nu: float
    cover_e_mpa: float
    film_along_e_mpa: float
    film_across_e_mpa: float
    core_e_mpa: float
    radius_mm: float
    interface: str  # "bonded" | "unbonded"

    @classmethod
    def from_sim(cls, sim: SimConfig, interface: str) -> Section:
        if interface not in ("bonded", "unbonded"):
            raise ValueError(f"interface={interface!r}: must be 'bonded' or 'unbonded'")
        sp_, sh = sim.spacer, sim.sheet
        t_film = sh.film_thickness_mm + sh.copper_thickness_mm
        pi_a = sh.film_modulus_mpa * sh.film_thickness_mm  # N/mm tension stiffness per width
        cu_a = sh.copper_modulus_mpa * sh.copper_thickness_mm
        along = pi_a + sh.electrode_fill * cu_a
        across = 1.0 / (sh.electrode_fill / (pi_a + cu_a) + (1.0 - sh.electrode_fill) / pi_a)
        return cls(width_mm=sp_.width_mm, lattice_mm=sp_.thickness_mm, pitch_mm=sp_.cell_mm,
                   wall_mm=BAND_SHARE * sp_.solid_fraction * sp_.cell_mm, solid_fraction=sp_.solid_fraction, cover_mm=sim.cover.thickness_mm, film_mm=t_film,
                   core_mm=sh.velostat_thickness_mm, slip_mm=0.005, silicone_e_mpa=sp_.modulus_kpa * KPA,
                   silicone_nu=sp_.poisson, cover_e_mpa=sim.cover.modulus_kpa * KPA,
                   film_along_e_mpa=along / t_film, film_across_e_mpa=across / t_film,
                   core_e_mpa=sh.velostat_modulus_mpa, radius_mm=rig.INDENTER_RADIUS_MM,
                   interface=interface)


# layer names, bottom to top, with their element rows (thickness split evenly)
LAYERS = ("lattice", "film_across", "slip_low", "core", "slip_high", "film_along", "cover")


def _x_edges(sec: Section, wall_elems: int, void_elems: int, fine_mm: float = 7.0) -> tuple[np.ndarray, np.ndarray]:
    """Element edges along the section and, per element, whether it lies in a wall. Walls are
    centred on multiples of the pitch (one under the cap's start position x = 0); the pad's rim
    (beyond the last full wall) is solid. Beyond fine_mm from the centre, where the sheet has
    spread the load into a smooth field, walls and voids get two elements each."""
    half = 0.5 * sec.width_mm
    p, w = sec.pitch_mm, sec.wall_mm
    edges, wall = [-half], []
    k_last = int(np.floor((half - 0.5 * w) / p))

    def fill(to, n, solid):
        edges.extend(np.linspace(edges[-1], to, n + 1)[1:])
        wall.extend([solid] * n)

    for k in range(-k_last, k_last + 1):
        lo, hi = k * p - 0.5 * w, k * p + 0.5 * w
        fine = abs(k * p) <= fine_mm
        nw, nv = (wall_elems, void_elems) if fine else (2, 2)
        if lo > edges[-1] + 1e-9:  # void (or the rim, solid) before this wall
            fill(lo, max(1, round(nv * (lo - edges[-1]) / (p - w))), k == -k_last)
        fill(hi, nw, True)
    if half > edges[-1] + 1e-9:
        fill(half, max(1, round(2 * (half - edges[-1]) / (p - w))), True)
    return np.array(edges), np.array(wall)


@dataclass
class Mesh:
    points: np.ndarray  # (n, 2) reference coordinates
    cells: np.ndarray  # (m, 9) quad9 (VTK order)
    layer: np.ndarray  # (m,) index into LAYERS
    wall: np.ndarray  # (m,) lattice element in a wall (False: void medium; True outside the lattice)
    column: np.ndarray  # (m,) element column
    x_edges: np.ndarray
    z_edges: np.ndarray
    top_nodes: np.ndarray  # cover surface nodes, left to right
    top_weights: np.ndarray  # their tributary lengths (Simpson lumping of a quadratic edge)
    base_nodes: np.ndarray


def build_mesh(sec: Section, wall_elems: int = 3, void_elems: int = 4, lattice_rows: int = 5) -> Mesh:
    xe, wall_col = _x_edges(sec, wall_elems, void_elems)
    rows = {"lattice": (sec.lattice_mm, lattice_rows), "film_across": (sec.film_mm, 1),
            "slip_low": (sec.slip_mm, 1), "core": (sec.core_mm - 2 * sec.slip_mm, 2),
            "slip_high": (sec.slip_mm, 1), "film_along": (sec.film_mm, 1), "cover": (sec.cover_mm, 2)}
    ze, row_layer = [0.0], []
    for li, name in enumerate(LAYERS):
        t, n = rows[name]
        ze += list(ze[-1] + np.linspace(0.0, t, n + 1)[1:])
        row_layer += [li] * n
    ze = np.array(ze)
    # node grid at half-element spacing
    xn = np.empty(2 * len(xe) - 1)
    xn[0::2], xn[1::2] = xe, 0.5 * (xe[:-1] + xe[1:])
    zn = np.empty(2 * len(ze) - 1)
    zn[0::2], zn[1::2] = ze, 0.5 * (ze[:-1] + ze[1:])
    nxn = len(xn)
    nzn = len(zn)
    X, Z = np.meshgrid(xn, zn, indexing="ij")  # [ix, iz]: numbered through the thickness first,
    points = np.column_stack([X.ravel(), Z.ravel()])  # which keeps the stiffness matrix narrowly banded

    def nid(iz, ix):
        return ix * nzn + iz

    cells, layer, wall, column = [], [], [], []
    for r in range(len(ze) - 1):
        for c in range(len(xe) - 1):
            i, j = 2 * c, 2 * r
            cells.append([nid(j, i), nid(j, i + 2), nid(j + 2, i + 2), nid(j + 2, i),
                          nid(j, i + 1), nid(j + 1, i + 2), nid(j + 2, i + 1), nid(j + 1, i), nid(j + 1, i + 1)])
            layer.append(row_layer[r])
            wall.append(bool(wall_col[c]) or row_layer[r] != 0)
            column.append(c)
    top = np.array([nid(len(zn) - 1, i) for i in range(nxn)])
    w = np.zeros(nxn)
    for c in range(len(xe) - 1):  # Simpson lumping on each quadratic edge: L/6, 4L/6, L/6
        length = xe[c + 1] - xe[c]
        w[2 * c] += length / 6
        w[2 * c + 1] += 4 * length / 6
        w[2 * c + 2] += length / 6
    base = np.array([nid(0, i) for i in range(nxn)])
    return Mesh(points, np.array(cells), np.array(layer), np.array(wall), np.array(column), xe, ze, top, w, base)


def _neo_hooke(e_mpa: float, nu: float):
    mu = e_mpa / (2 * (1 + nu))
    bulk = e_mpa / (3 * (1 - 2 * nu))
    return fem.NeoHooke(mu=mu, bulk=bulk)


def materials(sec: Section, mesh: Mesh) -> list[tuple[np.ndarray, object]]:
    """(cell mask, felupe material) per material region."""
    lay = mesh.layer
    idx = {n: i for i, n in enumerate(LAYERS)}
    core = _neo_hooke(sec.core_e_mpa, 0.4)
    if sec.interface == "bonded":
        slip = core
    else:  # pressure passes, shear does not: the core's bulk modulus, a vanishing shear modulus
        k_core = sec.core_e_mpa / (3 * (1 - 2 * 0.4))
        slip = fem.NeoHooke(mu=1e-7 * sec.core_e_mpa, bulk=k_core)
    # the walls along the section, smeared over the voids: their silicone share of the plan
    # (1 - BAND_SHARE) rho over the voids' fraction of the section carries the honeycomb's
    # transverse shear G rho / 2 (Gibson & Ashby) and its share of compression, with no lateral
    # coupling (nu = 0: the voids let it bulge). Its -mu ln J term stiffens without bound as a
    # cell is squeezed flat, which carries the walls' contact when it closes (as a third medium:
    # Wriggers, Schroder & Auricchio 2013).
    void_fraction = 1.0 - sec.wall_mm / sec.pitch_mm
    g_s = sec.silicone_e_mpa / (2 * (1 + sec.silicone_nu))
    mu_fill = 0.5 * sec.solid_fraction * g_s / void_fraction
    void = fem.NeoHookeCompressible(mu=mu_fill, lmbda=0.0)
    out = [
        ((lay == idx["lattice"]) & mesh.wall, _neo_hooke(sec.silicone_e_mpa, sec.silicone_nu)),
        ((lay == idx["lattice"]) & ~mesh.wall, void),
        (lay == idx["film_across"], _neo_hooke(sec.film_across_e_mpa, 0.34)),
        (lay == idx["film_along"], _neo_hooke(sec.film_along_e_mpa, 0.34)),
        (lay == idx["core"], core),
        ((lay == idx["slip_low"]) | (lay == idx["slip_high"]), slip),
        (lay == idx["cover"], _neo_hooke(sec.cover_e_mpa, sec.silicone_nu)),
    ]
    return [(m, u) for m, u in out if m.any()]


@dataclass
class CapContact:
    """Penalty contact of the rigid cylinder (centre c, radius R) with the cover's surface nodes.

    Each node carries a tributary length w. A free node penetrating the cylinder by g is pushed
    out along the normal with eps w g (frictionless). A stuck node is tied to the point of the
    cap where it stuck (anchor, in the cap's frame) by eps w times its distance from it (no
    slip); it is released when the tie pulls it towards the cap's centre less than it pushes."""

    nodes: np.ndarray
    weights: np.ndarray
    radius: float
    eps: float  # N/mm^3: penalty per length of surface per mm of penetration
    stuck: np.ndarray = field(default=None)
    anchor: np.ndarray = field(default=None)

    def __post_init__(self):
        self.stuck = np.zeros(len(self.nodes), bool)
        self.anchor = np.zeros((len(self.nodes), 2))

    def forces(self, x: np.ndarray, centre: np.ndarray) -> tuple[np.ndarray, list, np.ndarray]:
        """Forces on the nodes from the cap (n, 2), their 2x2 stiffness blocks (the derivative of
        minus the force), and each node's normal contact force per length (N/mm^2 = MPa)."""
        d = x - centre
        dist = np.linalg.norm(d, axis=1)
        n = d / dist[:, None]
        gap = self.radius - dist  # penetration > 0
        f = np.zeros_like(x)
        k = np.zeros((len(x), 2, 2))
        eye = np.eye(2)
        free = ~self.stuck & (gap > 0)
        kw = self.eps * self.weights
        nn = n[:, :, None] * n[:, None, :]
        f[free] = (kw[free] * gap[free])[:, None] * n[free]
        k[free] = kw[free, None, None] * (nn[free] - (gap[free] / dist[free])[:, None, None] * (eye - nn[free]))
        s = self.stuck
        f[s] = -kw[s, None] * (x[s] - (centre + self.anchor[s]))
        k[s] = kw[s, None, None] * eye
        normal = np.einsum("ij,ij->i", f, n) / self.weights
        return f, k, normal


class StackFE:
    """The section, its fields and bodies, and a Newton solver with the cap's contact."""

    def __init__(self, sec: Section, wall_elems: int = 3, void_elems: int = 4, lattice_rows: int = 5,
                 penalty: float = 2.0e3):
        self.sec = sec
        self.mesh = build_mesh(sec, wall_elems, void_elems, lattice_rows)
        m = self.mesh
        self.height_mm = float(m.z_edges[-1])
        self.bodies, self.fields, self.regions = [], [], []
        first = None
        for mask, umat in materials(sec, m):
            mesh_k = fem.Mesh(m.points, m.cells[mask], "quad9")
            region = fem.RegionBiQuadraticQuad(mesh_k)
            fld = fem.FieldContainer([fem.FieldPlaneStrain(region, dim=2)])
            if first is None:
                first = fld
            else:
                fld.link(first)
            self.bodies.append((mask, fem.SolidBody(umat, fld)))
            self.fields.append(fld)
            self.regions.append(region)
        self.u = first[0].values  # (n, 2) shared displacement array
        n = len(m.points)
        fixed = np.zeros((n, 2), bool)
        fixed[m.base_nodes] = True
        self.free = np.flatnonzero(~fixed.ravel())
        self.contact = CapContact(m.top_nodes, m.top_weights, sec.radius_mm, penalty)
        self.centre = np.array([0.0, self.height_mm + sec.radius_mm])
        self.max_step_mm = 0.15

    def move_to(self, centre: np.ndarray, sticking: bool, step_mm: float = 0.02, min_step_mm: float = 1e-4) -> int:
        """Move the cap from where it is to `centre` in increments of at most step_mm, halving an
        increment whose equilibrium fails (the state is restored first). Returns Newton iterations."""
        target = np.asarray(centre, float)
        total = 0
        h = step_mm
        while True:
            gap = target - self.centre
            dist = float(np.linalg.norm(gap))
            if dist < 1e-12:
                return total
            step = min(h, dist)
            saved = (self.u.copy(), self.centre.copy(), self.contact.stuck.copy(), self.contact.anchor.copy())
            try:
                with np.errstate(all="ignore"):
                    total += self.solve_at(self.centre + gap * (step / dist), sticking)
                h = min(step_mm, 1.5 * h)
            except (RuntimeError, FloatingPointError, np.linalg.LinAlgError):
                self.u[:] = saved[0]
                self.centre = saved[1]
                self.contact.stuck[:], self.contact.anchor[:] = saved[2], saved[3]
                h = 0.5 * step
                if h < min_step_mm:
                    raise

    # -------------------------------------------------------------- assembly and Newton
    def _system(self):
        n = self.u.size
        r = np.zeros(n)
        K = sp.csr_matrix((n, n))
        for (_, body), fld in zip(self.bodies, self.fields, strict=True):
            r += np.asarray(body.assemble.vector(fld).todense()).ravel()
            K = K + body.assemble.matrix(fld)
        nodes = self.contact.nodes
        x = self.mesh.points[nodes] + self.u[nodes]
        f, k, normal = self.contact.forces(x, self.centre)
        dof = np.column_stack([2 * nodes, 2 * nodes + 1])
        r[dof.ravel()] -= f.ravel()
        rows = np.repeat(dof, 2, axis=1).ravel()
        cols = np.tile(dof, (1, 2)).ravel()
        K = K + sp.csr_matrix((k.ravel(), (rows, cols)), shape=(n, n))
        return r, K, f, normal

    def newton(self, tol: float = 1e-7, max_iter: int = 25) -> int:
        """Equilibrium at the cap's current position; returns iterations (raises on failure)."""
        scale = None
        for it in range(1, max_iter + 1):
            r, K, f, _ = self._system()
            rf = r[self.free]
            if scale is None:
                scale = max(np.abs(f).sum(), 1e-6)
            if np.linalg.norm(rf) < tol * scale and it > 1:
                return it
            if not np.all(np.isfinite(K.data)) or not np.all(np.isfinite(rf)):
                raise FloatingPointError("inverted element")
            du = spsolve(K[self.free][:, self.free].tocsc(), -rf)
            if not np.all(np.isfinite(du)):
                raise FloatingPointError("singular tangent")
            big = np.abs(du).max()
            if big > self.max_step_mm:  # a Newton step larger than this inverts the thin layers' cells
                du *= self.max_step_mm / big
            flat = self.u.reshape(-1)
            flat[self.free] += du
            if np.abs(du).max() < 1e-10 * max(1.0, np.abs(flat).max()) and it > 2:
                return it
        raise RuntimeError(f"no convergence in {max_iter} iterations (|r| = {np.linalg.norm(rf):.3g})")

    def solve_at(self, centre: np.ndarray, sticking: bool, max_active_passes: int = 4) -> int:
        """Move the cap to `centre` and find equilibrium; in the sticking phase, nodes that have
        come into contact stick where they touch and tensile ties are released, until the set
        settles. Returns the Newton iterations spent."""
        self.centre = np.asarray(centre, float)
        total = 0
        for _ in range(max_active_passes):
            total += self.newton()
            if not sticking:
                return total
            c = self.contact
            x = self.mesh.points[c.nodes] + self.u[c.nodes]
            _, _, normal = c.forces(x, self.centre)
            d = x - self.centre
            gap = c.radius - np.linalg.norm(d, axis=1)
            new = ~c.stuck & (gap > 0)
            release = c.stuck & (normal < 0)
            if not new.any() and not release.any():
                return total
            # a new contact sticks at its projection onto the cap's surface
            proj = d[new] / np.linalg.norm(d[new], axis=1)[:, None] * c.radius
            c.anchor[new] = proj
            c.stuck[new] = True
            c.stuck[release] = False
        return total

    def stick_all_in_contact(self) -> None:
        """Start of the shear phase: every node in contact sticks where it is."""
        c = self.contact
        x = self.mesh.points[c.nodes] + self.u[c.nodes]
        d = x - self.centre
        gap = c.radius - np.linalg.norm(d, axis=1)
        on = gap > 0
        c.stuck[:] = on
        c.anchor[on] = d[on]  # where it is now (the tie's rest length is its penetration)

    # -------------------------------------------------------------- results
    def state(self) -> dict:
        """Per-layer pressure profiles and the contact at the current equilibrium."""
        m = self.mesh
        _, _, f, normal = self._system()
        # forces on the skin (the fast model's convention): F_x along +x, F_z > 0 compressive
        fx, fz = float(f[:, 0].sum()), -float(f[:, 1].sum())
        in_contact = normal > 1e-9
        x_top = m.points[m.top_nodes, 0] + self.u[m.top_nodes, 0]
        out = {"cap_x_mm": float(self.centre[0]), "depth_mm": float(self.height_mm + self.sec.radius_mm - self.centre[1]),
               "fx_n_per_mm": fx, "fz_n_per_mm": fz,
               "contact_from_mm": float(x_top[in_contact].min()) if in_contact.any() else np.nan,
               "contact_to_mm": float(x_top[in_contact].max()) if in_contact.any() else np.nan,
               "contact_x_mm": x_top, "contact_kpa": normal / KPA,
               "stuck_fraction": float(self.contact.stuck[in_contact].mean()) if in_contact.any() else 0.0}
        core, deep = self._layer_pressure("core"), self._layer_pressure("lattice", bottom=True)
        out["superficial_x_mm"], out["superficial_kpa"] = core
        out["deep_x_mm"], out["deep_kpa"] = deep
        # the superficial sheet's lateral displacement (its core's mean, under the cap's start)
        out["sheet_shift_mm"] = float(self._core_shift())
        out["sheet_x_under_cap_mm"] = float(self._core_point_under(self.centre[0]))
        out["max_lattice_strain"] = float(self._max_compression())
        return out

    def _quadrature_stress(self, li: int, bottom: bool = False):
        """Reference x of the quadrature points and the through-thickness compressive stress
        (MPa) on the layer's material plane, for the cells of layer li (bottom row only if asked)."""
        xs, ps = [], []
        for (mask, body), fld, region in zip(self.bodies, self.fields, self.regions, strict=True):
            sel = np.flatnonzero(self.mesh.layer[mask] == li)
            if len(sel) == 0:
                continue
            sigma = body.evaluate.cauchy_stress(fld)  # (3, 3, q, cells) in plane strain
            F = fld.extract()[0]  # deformation gradient (3, 3, q, cells)
            Finv_t = np.linalg.inv(F[:2, :2].transpose(2, 3, 0, 1)).transpose(0, 1, 3, 2)  # (q, c, 2, 2) F^-T
            nrm = Finv_t[..., :, 1]  # F^-T e_z: the normal of the deformed material plane z = const
            nrm = nrm / np.linalg.norm(nrm, axis=-1, keepdims=True)
            s = sigma[:2, :2].transpose(2, 3, 0, 1)  # (q, c, 2, 2)
            snn = np.einsum("qci,qcij,qcj->qc", nrm, s, nrm)
            cells = self.mesh.cells[mask]
            # reference coordinates of the quadrature points
            h = region.h[..., 0]  # (9, q) shape functions at the quadrature points
            xq = np.einsum("aq,ca->qc", h, self.mesh.points[cells, 0])
            zq = np.einsum("aq,ca->qc", h, self.mesh.points[cells, 1])
            if bottom:
                keep = zq[:, sel] < zq[:, sel].min() + 1e-9 + 0.5 * (self.mesh.z_edges[1] - self.mesh.z_edges[0]) * 0.3
                xsel, psel = xq[:, sel][keep], -snn[:, sel][keep]
            else:
                xsel, psel = xq[:, sel].ravel(), -snn[:, sel].ravel()
            xs.append(xsel.ravel())
            ps.append(psel.ravel())
        x = np.concatenate(xs)
        p = np.concatenate(ps)
        if not bottom:  # mean over the layer's quadrature rows at each x
            ux, inv = np.unique(np.round(x, 9), return_inverse=True)
            return ux, np.bincount(inv, p) / np.bincount(inv)
        order = np.argsort(x)
        return x[order], p[order]

    def _layer_pressure(self, name: str, bottom: bool = False):
        x, p = self._quadrature_stress(LAYERS.index(name), bottom)
        return x, p / KPA

    def _core_shift(self) -> float:
        m = self.mesh
        li = LAYERS.index("core")
        nodes = np.unique(m.cells[m.layer == li])
        near = nodes[np.abs(m.points[nodes, 0]) < 0.5 * self.sec.width_mm]
        return float(self.u[near, 0].mean())

    def _core_point_under(self, x_mm: float) -> float:
        """Reference x (the superficial sheet's own frame) of the core's mid-plane point that now
        lies at x_mm."""
        m = self.mesh
        nodes = np.unique(m.cells[m.layer == LAYERS.index("core")])
        z = m.points[nodes, 1]
        mid = nodes[np.isclose(z, np.median(np.unique(z)))]
        xr = m.points[mid, 0]
        order = np.argsort(xr)
        return float(np.interp(x_mm, (xr + self.u[mid, 0])[order], xr[order]))

    def _max_compression(self) -> float:
        m = self.mesh
        top = np.flatnonzero(np.isclose(m.points[:, 1], self.sec.lattice_mm))
        return float(-self.u[top, 1].min() / self.sec.lattice_mm)
