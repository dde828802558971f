"""A plane-strain finite-element section of the two-layer skin under a rigid cylindrical cap
(felupe: finite-strain hyperelasticity, bi-quadratic quads).

What is modelled, from the base up (lengths mm, stresses MPa = N/mm^2, forces N per mm of
section depth):
- the base: rigid, the deep FSR sheet bonded to it;
- the deep FSR sheet as its three layers (film, Velostat core, film), so its bending spreads the
  walls' load before the deep Velostat reads it, as in the skin;
- the lattice spacer as cells: the walls crossing the section (two thirds of a hexagonal
  honeycomb's wall material) as vertical silicone walls at the cell pitch; the walls lying
  along it (the other third) smeared over the voids as a compressible medium that carries the
  honeycomb's transverse shear G rho / 2 and whose energy grows without bound as a cell is
  squeezed flat (it carries the walls' contact when a cell closes, like a third medium:
  Wriggers, Schroder & Auricchio 2013). The walls' width is the honeycomb's share times
  (1 - nu^2): a plane-strain wall is stiffer by 1 / (1 - nu^2) in compression than the
  honeycomb's free-edged one, so the section's through-thickness modulus is the honeycomb's
  rho E (Gibson & Ashby, Cellular Solids, 2nd ed. 1997, sec. 4.4: E3 = rho E_s, G13 = rho G_s / 2
  for regular hexagons). tests/sim/test_fem_reference.py checks both moduli on a periodic strip;
- the superficial FSR sheet as its three layers: the film whose copper strips run along the
  section (polyimide + copper, homogenised), the Velostat core, the film whose strips cross the
  section (strips and polyimide gaps in series); films and core bonded (the glued bound);
- the 0.2 mm silicone cover;
- the rigid cap, a cylinder of the hemisphere's radius (the section's indenter), pressed by
  penalty contact: frictionless while it presses in, sticking (no slip) during the shear
  phase, with nodes that come into contact while shearing stuck where they touch and nodes
  whose contact force turns tensile released.

Each layer's pressure is the normal load it transmits, read from the solution's nodal forces:
the internal forces of the elements above a horizontal node line, on that line, are the force
the material below exerts across it (their sum is the cap's load, exactly, at equilibrium).
A lumped (Simpson) tributary length per node turns them into a traction profile whose sum
sum(p w) is the transmitted force. The superficial layer is read across its Velostat core's
mid-plane, the deep layer across its own, the lattice-to-deep-sheet interface and the base as
well. Nothing of the fast model's contact law, plate theory, couple response or shear
stiffness is used.

Only the bonded film interface is modelled. A frictionless (unbonded) interface was once
approximated by a 5 um solid layer with 1e-7 of the core's shear modulus: that tangent is
near-singular (a symmetric press gave a 0.19 mm lateral offset, the core's stress swung to
-164 kPa under +50 kPa of contact pressure), and a well-posed version needs frictional contact
between deformable bodies, which felupe does not provide. The bonded bound is the glued sandwich.

What the section misses (state it beside every comparison): it is a line contact, infinite
along the cap's axis (forces are per mm; a hemisphere's load spreads in two directions, a
cylinder's in one); the walls are plane-strain plates (they also bend, which a honeycomb's
walls loaded in their own plane hardly do: +~10 % on the transverse shear modulus); the
films' strips are homogenised; the air in closed cells is ignored.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import felupe as fem
import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import spsolve

from layerskin_exp import rig
from layerskin_exp.sim.config import SimConfig
from layerskin_exp.sim.spacer_config import CROSSING_SHARE

KPA = 1e-3  # MPa per kPa
# A regular hexagonal honeycomb has its walls in three directions. Cut along one of them, two
# thirds of the wall material crosses the section (the walls at +-60 deg, drawn as bands) and one
# third lies along it (the walls parallel to the section, which carry shear along x by their
# in-plane stiffness and which a plane-strain section can only smear over the voids).
BAND_SHARE = CROSSING_SHARE
FILM_NU = 0.34  # polyimide (and the films' homogenised copper strips)
CORE_NU = 0.4  # Velostat (carbon-loaded polyolefin)


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
    silicone_e_mpa: float
    silicone_nu: float
    cover_e_mpa: float
    film_along_e_mpa: float
    film_across_e_mpa: float
    core_e_mpa: float
    radius_mm: float
    deep_sheet: bool = True  # False: the lattice bonded to the rigid base (the closed-form checks)
    # True: the lattice as one homogenised layer (`homogenised_lattice`) instead of walls and
    # smeared medium, inside the same solid rim: the section's own measure of what its cells do to
    # each compared quantity
    homogenised: bool = False
    # with `homogenised`: False puts the homogenised lattice out to the pad's sides, without the
    # solid rim (the lattice of the 3D half-model, `shear3d`)
    rim: bool = True
    # the cover's Poisson ratio; None: the spacer's silicone_nu (the simulator has one for both).
    # Its neo-Hooke's volume term resists at most ~K = E / 3(1 - 2 nu) of pressure (0.58 MPa at
    # 0.49): `--cover-poisson` measures what that choice does to each compared quantity
    cover_nu: float | None = None

    @classmethod
    def from_sim(cls, sim: SimConfig) -> Section:
        sp_, sh = sim.spacer, sim.sheet
        t_film = sh.film_thickness_mm + sh.copper_thickness_mm
        pi_a = sh.film_modulus_mpa * sh.film_thickness_mm  # N/mm tension stiffness per width
        cu_a = sh.copper_modulus_mpa * sh.copper_thickness_mm
        along = pi_a + sh.electrode_fill * cu_a
        across = 1.0 / (sh.electrode_fill / (pi_a + cu_a) + (1.0 - sh.electrode_fill) / pi_a)
        wall = sp_.section_wall_mm
        return cls(width_mm=sp_.width_mm, lattice_mm=sp_.thickness_mm, pitch_mm=sp_.cell_mm,
                   wall_mm=wall, solid_fraction=sp_.solid_fraction, cover_mm=sim.cover.thickness_mm,
                   film_mm=t_film, core_mm=sh.velostat_thickness_mm, silicone_e_mpa=sp_.modulus_kpa * KPA,
                   silicone_nu=sp_.poisson, cover_e_mpa=sim.cover.modulus_kpa * KPA,
                   film_along_e_mpa=along / t_film, film_across_e_mpa=across / t_film,
                   core_e_mpa=sh.velostat_modulus_mpa, radius_mm=rig.INDENTER_RADIUS_MM)

    def cover_poisson(self) -> float:
        return self.silicone_nu if self.cover_nu is None else self.cover_nu

    def honeycomb_moduli_kpa(self) -> tuple[float, float]:
        """The honeycomb's through-thickness Young's modulus and transverse shear modulus
        (Gibson & Ashby 1997, sec. 4.4; regular hexagons): rho E_s and rho G_s / 2."""
        e = self.silicone_e_mpa / KPA
        return self.solid_fraction * e, 0.5 * self.solid_fraction * e / (2 * (1 + self.silicone_nu))


@dataclass(frozen=True)
class Mesher:
    """Element counts of the section. `refine` multiplies the rows of the thin layers and the
    elements of the coarse region; a refinement study doubles every count."""

    wall_elems: int = 3
    void_elems: int = 4
    lattice_rows: int = 5
    refine: int = 1

    def finer(self) -> Mesher:
        return Mesher(2 * self.wall_elems, 2 * self.void_elems, 2 * self.lattice_rows, 2 * self.refine)


# layer names, bottom to top, with their element rows (thickness split evenly)
LAYERS = ("deep_film_along", "deep_core", "deep_film_across", "lattice", "film_across", "core",
          "film_along", "cover")


def _last_wall(sec: Section) -> int:
    """Index k of the last full wall (centred at k pitch) inside the pad's half-width."""
    return int(np.floor((0.5 * sec.width_mm - 0.5 * sec.wall_mm) / sec.pitch_mm + 1e-9))


def rim_from_mm(sec: Section) -> float:
    """Where the pad's solid rim begins, |x| (mm): the outer face of the last full wall."""
    return _last_wall(sec) * sec.pitch_mm + 0.5 * sec.wall_mm


def _x_edges(sec: Section, wall_elems: int, void_elems: int, coarse: int, fine_mm: float = 7.0
             ) -> tuple[np.ndarray, np.ndarray]:
    """Element edges along the section and, per element, whether it lies in a wall. Walls are
    centred on multiples of the pitch (one under the cap's start position x = 0); the pad's rim
    (beyond the last full wall, `rim_from_mm`) is solid. Beyond fine_mm from the centre, where
    the sheet has spread the load into a smooth field, walls and voids get `coarse` elements each."""
    half = 0.5 * sec.width_mm
    p, w = sec.pitch_mm, sec.wall_mm
    edges, wall = [-half], []
    k_last = _last_wall(sec)

    def fill(to, n, solid):
        edges.extend(np.linspace(edges[-1], to, n + 1)[1:])
        wall.extend([solid] * n)

    for k in range(-k_last, k_last + 1):
        lo, hi = k * p - 0.5 * w, k * p + 0.5 * w
        fine = abs(k * p) <= fine_mm
        nw, nv = (wall_elems, void_elems) if fine else (coarse, coarse)
        if lo > edges[-1] + 1e-9:  # void (or the rim, solid) before this wall
            fill(lo, max(1, round(nv * (lo - edges[-1]) / (p - w))), k == -k_last)
        fill(hi, nw, True)
    if half > edges[-1] + 1e-9:
        fill(half, max(1, round(coarse * (half - edges[-1]) / (p - w))), True)
    return np.array(edges), np.array(wall)


@dataclass
class Mesh:
    points: np.ndarray  # (n, 2) reference coordinates
    cells: np.ndarray  # (m, 9) quad9 (VTK order)
    layer: np.ndarray  # (m,) index into the stack's layer names
    wall: np.ndarray  # (m,) lattice element in a wall (False: void medium; True outside the lattice)
    names: tuple  # the stack's layer names, bottom to top
    x_edges: np.ndarray
    z_edges: np.ndarray
    layer_z: dict  # name -> (bottom, top) reference heights
    top_nodes: np.ndarray  # cover surface nodes, left to right
    top_weights: np.ndarray  # their tributary lengths (Simpson lumping of a quadratic edge; ring areas when axisymmetric)
    base_nodes: np.ndarray
    axisymmetric: bool = False  # x is the radius: the solid of revolution about x = 0

    def line_nodes(self, z_mm: float) -> np.ndarray:
        """The nodes on the horizontal line z = z_mm (an element edge), left to right."""
        on = np.flatnonzero(np.isclose(self.points[:, 1], z_mm, atol=1e-9))
        if len(on) == 0:
            raise ValueError(f"no node line at z = {z_mm} mm")
        return on[np.argsort(self.points[on, 0])]

    def line_weights(self) -> np.ndarray:
        """Simpson tributary lengths of a node line's nodes (every line has the same x); for a
        solid of revolution, the rings' areas 2 pi r w (mm^2)."""
        return ring_weights(self.x_edges) if self.axisymmetric else simpson_weights(self.x_edges)


def simpson_weights(x_edges: np.ndarray) -> np.ndarray:
    """Lumped tributary lengths of the nodes of a line of quadratic edges (corners and mid-points
    alternating): L/6, 4L/6, L/6 per edge. A uniform traction's consistent nodal forces divided
    by them give it back at every node."""
    w = np.zeros(2 * len(x_edges) - 1)
    for c in range(len(x_edges) - 1):
        length = x_edges[c + 1] - x_edges[c]
        w[2 * c] += length / 6
        w[2 * c + 1] += 4 * length / 6
        w[2 * c + 2] += length / 6
    return w


def ring_weights(r_edges: np.ndarray) -> np.ndarray:
    """A solid of revolution's node areas on a line of quadratic edges: 2 pi int N_i r dr per
    node (exact; the axis node's is 0, as a uniform pressure puts no force on it)."""
    g, gw = np.polynomial.legendre.leggauss(4)
    t, gw = 0.5 * (g + 1.0), 0.5 * gw
    shape = np.stack([(1 - t) * (1 - 2 * t), 4 * t * (1 - t), t * (2 * t - 1)])  # corner, mid, corner
    w = np.zeros(2 * len(r_edges) - 1)
    for c in range(len(r_edges) - 1):
        a, b = r_edges[c], r_edges[c + 1]
        r = a + (b - a) * t
        w[2 * c:2 * c + 3] += 2 * np.pi * (shape * r * gw).sum(axis=1) * (b - a)
    return w


def stack_rows(sec: Section, mesher: Mesher) -> list[tuple[str, float, int]]:
    """(layer, thickness mm, element rows), bottom to top."""
    r = mesher.refine
    sheet = [("film_across", sec.film_mm, r), ("core", sec.core_mm, 2 * r), ("film_along", sec.film_mm, r)]
    deep = [("deep_film_along", sec.film_mm, r), ("deep_core", sec.core_mm, 2 * r),
            ("deep_film_across", sec.film_mm, r)] if sec.deep_sheet else []
    return deep + [("lattice", sec.lattice_mm, mesher.lattice_rows)] + sheet + [("cover", sec.cover_mm, 2 * r)]


def build_mesh(sec: Section, mesher: Mesher = Mesher(), rows: list | None = None,
               x_edges: np.ndarray | None = None, axisymmetric: bool = False) -> Mesh:
    """The section's mesh. `rows` (layer, thickness, element rows) and `x_edges` replace the
    skin's stack and the lattice's cell pattern (the closed-form checks use a plain layer).
    `axisymmetric`: only x >= 0, read as the radius (the walls become rings, the pad a disc of
    the pad's half-width)."""
    rows = stack_rows(sec, mesher) if rows is None else rows
    if x_edges is None:
        xe, wall_col = _x_edges(sec, mesher.wall_elems, mesher.void_elems, 2 * mesher.refine)
    else:
        xe, wall_col = np.asarray(x_edges, float), np.ones(len(x_edges) - 1, bool)
    if axisymmetric:  # the right half, split at the axis where an element straddles it
        keep = xe[1:] > 1e-12
        wall_col = wall_col[keep]
        xe = np.concatenate([[0.0], xe[1:][keep]])
    names = tuple(name for name, _, _ in rows)
    ze, row_layer, layer_z = [0.0], [], {}
    for li, (name, t, n) in enumerate(rows):
        layer_z[name] = (ze[-1], ze[-1] + t)
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

    lattice = names.index("lattice") if "lattice" in names else -1
    cells, layer, wall = [], [], []
    for r in range(len(ze) - 1):
        for c in range(len(xe) - 1):
            i, j = 2 * c, 2 * r
            cells.append([nid(j, i), nid(j, i + 2), nid(j + 2, i + 2), nid(j + 2, i),
                          nid(j, i + 1), nid(j + 1, i + 2), nid(j + 2, i + 1), nid(j + 1, i), nid(j + 1, i + 1)])
            layer.append(row_layer[r])
            wall.append(bool(wall_col[c]) or row_layer[r] != lattice)
    top = np.array([nid(len(zn) - 1, i) for i in range(nxn)])
    base = np.array([nid(0, i) for i in range(nxn)])
    top_w = ring_weights(xe) if axisymmetric else simpson_weights(xe)
    return Mesh(points, np.array(cells), np.array(layer), np.array(wall), names, xe, ze, layer_z, top,
                top_w, base, axisymmetric)


def _neo_hooke(e_mpa: float, nu: float):
    mu = e_mpa / (2 * (1 + nu))
    bulk = e_mpa / (3 * (1 - 2 * nu))
    return fem.NeoHooke(mu=mu, bulk=bulk)


def fill_shear_modulus_mpa(sec: Section) -> float:
    """Shear modulus of the void medium: the crossing walls (fraction f of the section, shear
    modulus G_s) and the medium in series give the honeycomb's G13 = rho G_s / 2."""
    f = sec.wall_mm / sec.pitch_mm
    g_s = sec.silicone_e_mpa / (2 * (1 + sec.silicone_nu))
    g13 = 0.5 * sec.solid_fraction * g_s
    return (1.0 - f) / (1.0 / g13 - f / g_s)


def lattice_constants(sec: Section) -> dict:
    """The homogenised lattice's matrix shear modulus and bulk modulus (nu = 0) and its
    through-thickness stiffness k (MPa): E3 = 2 mu + k = rho E_s, G13 = mu = rho G_s / 2."""
    e3_kpa, g13_kpa = sec.honeycomb_moduli_kpa()
    mu = g13_kpa * KPA
    return {"mu": mu, "bulk": 2.0 * mu / 3.0, "k": e3_kpa * KPA - 2.0 * mu}


def plane_separation(k: float, axis: int) -> fem.Material:
    """W = k / 8 (s - 1)^2 with s = 1 / (C^-1)_aa, a = axis: the squared stretch of the distance
    between the material planes normal to the axis (h / H = 1 / |F^-T e_a|).

    In uniaxial stretch along the axis s is C_aa, so this is a fibre's W = k / 8 (C_aa - 1)^2 and
    gives the same through-thickness modulus; unlike the fibre, s does not change under a
    transverse simple shear (F = 1 + gamma e_x (x) e_a), so the term adds no shear stiffness at
    any preload. The fibre's C_aa grows as 1 + gamma^2 under that shear, so under a compressive
    preload (C_aa < 1) it softened the transverse shear tangent, mu + k (C_aa - 1) / 2, to zero at
    C_aa = 1 - 2 mu / k (0.495 here): a material instability the press to 3 N reaches (issue 28).
    A honeycomb's walls carry transverse shear in their own plane and the through-thickness load
    across planes z = const, which is what the planes' separation measures.

    With g = F^-T e_a, h = F^-1 g, b = g.g and s = 1 / b:
        P_kl = Q g_k h_l,  Q = k / 2 (s - 1) s^2,
        dP_kl / dF_mn = k s^3 (3 s - 2) g_k h_l g_m h_n
                        - Q (g_m Fi_nk h_l + g_k Fi_lm h_n + g_k g_m Ci_ln),
    Fi = F^-1, Ci = C^-1 (tests/sim/test_fem_shear3d.py checks both against finite differences).
    """

    def _parts(F):
        Fi = np.linalg.inv(np.moveaxis(F, (0, 1), (-2, -1)))  # (..., 3, 3)
        Fi = np.moveaxis(Fi, (-2, -1), (0, 1))
        g = Fi[axis]  # g_i = Fi_ai
        h = np.einsum("li...,i...->l...", Fi, g)
        s = 1.0 / np.einsum("i...,i...->...", g, g)
        return Fi, g, h, s

    def stress(x, k):
        F, statevars = x[0], x[-1]
        _, g, h, s = _parts(F)
        P = 0.5 * k * (s - 1.0) * s * s * np.einsum("k...,l...->kl...", g, h)
        return [P, statevars]

    def elasticity(x, k):
        F = x[0]
        Fi, g, h, s = _parts(F)
        q = 0.5 * k * (s - 1.0) * s * s
        gh = np.einsum("k...,l...->kl...", g, h)
        ci = np.einsum("la...,na...->ln...", Fi, Fi)
        A = k * s ** 3 * (3.0 * s - 2.0) * np.einsum("kl...,mn...->klmn...", gh, gh)
        A -= q * (np.einsum("m...,nk...,l...->klmn...", g, Fi, h) + np.einsum("k...,lm...,n...->klmn...", g, Fi, h)
                  + np.einsum("k...,m...,ln...->klmn...", g, g, ci))
        return [A]

    return fem.Material(stress, elasticity, k=k)


def homogenised_lattice(sec: Section, axis: int):
    """The lattice as a transversely isotropic solid about `axis` (the through-thickness one): a
    compressible neo-Hooke matrix (nu = 0) with the honeycomb's G13 = rho G_s / 2 plus a term on
    the separation of the planes normal to the axis (`plane_separation`), so that its
    through-thickness modulus is the honeycomb's E3 = rho E_s (Gibson & Ashby 1997, sec. 4.4);
    in-plane moduli are the matrix's, 2 G13."""
    c = lattice_constants(sec)
    return fem.CompositeMaterial(fem.NeoHookeCompressible(mu=c["mu"], lmbda=0.0), plane_separation(c["k"], axis))


def materials(sec: Section, mesh: Mesh) -> list[tuple[np.ndarray, object]]:
    """(cell mask, felupe material) per material region."""
    lay = mesh.layer

    def is_(*names):
        return np.isin(lay, [mesh.names.index(n) for n in names if n in mesh.names])

    # the walls along the section, smeared over the voids (lambda = 0: the voids let it bulge).
    # In the section the crossing walls and this medium alternate as vertical plies, which a
    # shear along x loads in series: 1 / G = f / G_s + (1 - f) / mu. The medium's mu is the one
    # that makes that laminate's G the honeycomb's transverse G13 = rho G_s / 2 (Gibson & Ashby).
    # Its -mu ln J term stiffens without bound as a cell is squeezed flat, which carries the
    # walls' contact when it closes (a third medium).
    mu_fill = fill_shear_modulus_mpa(sec)
    if sec.homogenised:
        # the cells homogenised, the pad's solid rim kept: the two sections differ by the cells only
        xc = mesh.points[mesh.cells[:, 8], 0]  # the quad9's centre node
        rim = is_("lattice") & (np.abs(xc) > rim_from_mm(sec)) & sec.rim
        lattice = [(is_("lattice") & ~rim, homogenised_lattice(sec, axis=1)),
                   (rim, _neo_hooke(sec.silicone_e_mpa, sec.silicone_nu))]
    else:
        lattice = [(is_("lattice") & mesh.wall, _neo_hooke(sec.silicone_e_mpa, sec.silicone_nu)),
                   (is_("lattice") & ~mesh.wall, fem.NeoHookeCompressible(mu=mu_fill, lmbda=0.0))]
    out = [
        *lattice,
        (is_("film_across", "deep_film_across"), _neo_hooke(sec.film_across_e_mpa, FILM_NU)),
        (is_("film_along", "deep_film_along"), _neo_hooke(sec.film_along_e_mpa, FILM_NU)),
        (is_("core", "deep_core"), _neo_hooke(sec.core_e_mpa, CORE_NU)),
        (is_("cover"), _neo_hooke(sec.cover_e_mpa, sec.cover_poisson())),
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
    dim: int = 2  # 3: a sphere's contact with a surface's nodes (weights: their areas, mm^2)
    # None: a free node touches while it penetrates. An array: the free nodes in contact are
    # these, held at their gap's sign either way (an active set, updated outside Newton)
    active: np.ndarray | None = None

    def __post_init__(self):
        self.stuck = np.zeros(len(self.nodes), bool)
        self.anchor = np.zeros((len(self.nodes), self.dim))

    def forces(self, x: np.ndarray, centre: np.ndarray) -> tuple[np.ndarray, list, np.ndarray]:
        """Forces on the nodes from the cap (n, 2), their 2x2 stiffness blocks (the derivative of
        minus the force), and each node's normal contact force per length (N/mm^2 = MPa)."""
        d = x - centre
        dist = np.linalg.norm(d, axis=1)
        n = d / dist[:, None]
        gap = self.radius - dist  # penetration > 0
        f = np.zeros_like(x)
        k = np.zeros((len(x), self.dim, self.dim))
        eye = np.eye(self.dim)
        free = ~self.stuck & ((gap > 0) if self.active is None else self.active)
        kw = self.eps * self.weights
        nn = n[:, :, None] * n[:, None, :]
        f[free] = (kw[free] * gap[free])[:, None] * n[free]
        k[free] = kw[free, None, None] * (nn[free] - (gap[free] / dist[free])[:, None, None] * (eye - nn[free]))
        s = self.stuck
        f[s] = -kw[s, None] * (x[s] - (centre + self.anchor[s]))
        k[s] = kw[s, None, None] * eye
        normal = np.einsum("ij,ij->i", f, n) / self.weights
        return f, k, normal


def moment_scale(fz: float, fx: float, load_x_mm: float, load_height_mm: float) -> float:
    """What a first-moment error is judged against (N mm / mm): the load's moment about the
    line's origin, or F_z x 1 mm where that is smaller (a centred press has none)."""
    return max(abs(fz * load_x_mm) + abs(fx * load_height_mm), abs(fz) * 1.0, 1e-12)


class StackFE:
    """The section, its fields and bodies, and a Newton solver with the cap's contact.

    `mesh` and `mats` (cell mask, felupe material) replace the skin's section (the closed-form
    checks solve a plain layer with the same machinery)."""

    def __init__(self, sec: Section, mesher: Mesher = Mesher(), penalty: float = 2.0e3,
                 mesh: Mesh | None = None, mats: list | None = None):
        self.sec = sec
        self.mesher = mesher
        self.mesh = build_mesh(sec, mesher) if mesh is None else mesh
        m = self.mesh
        self.height_mm = float(m.z_edges[-1])
        self.bodies, self.fields = [], []
        self._first = None
        for mask, umat in (materials(sec, m) if mats is None else mats):
            body, fld = self._body(mask, umat)
            self.bodies.append((mask, body))
            self.fields.append(fld)
        n = len(m.points)
        self.u = np.zeros((n, 2))  # (x, z) displacements; the fields get them at each assembly (_sync)
        # felupe's axisymmetric fields take (axial, radial) = (z, r): our degrees of freedom swapped
        self._perm = np.arange(2 * n).reshape(-1, 2)[:, ::-1].ravel() if m.axisymmetric else None
        self.free = np.flatnonzero(~self._fixed().ravel())
        self.contact = CapContact(m.top_nodes, m.top_weights, sec.radius_mm, penalty)
        self.centre = np.array([0.0, self.height_mm + sec.radius_mm])
        self.max_step_mm = 0.15
        # A solid of revolution's ring forces span 2 pi r (0 on the axis to 80 mm at the rim): its
        # residual's round-off floor is ~1e-8 of the load, above the section's 1e-7 at small loads.
        self.newton_tol = 1e-5 if m.axisymmetric else 1e-7
        self._probes: dict = {}

    def _fixed(self) -> np.ndarray:
        """(n, 2) fixed degrees of freedom: the base; on the axis of a solid of revolution, u_r."""
        m = self.mesh
        fixed = np.zeros((len(m.points), 2), bool)
        fixed[m.base_nodes] = True
        if m.axisymmetric:
            fixed[np.isclose(m.points[:, 0], 0.0), 0] = True
        return fixed

    def _sync(self) -> None:
        self._first[0].values[:] = self.u[:, ::-1] if self.mesh.axisymmetric else self.u

    def _ours(self, vec: np.ndarray) -> np.ndarray:
        return vec if self._perm is None else vec[self._perm]

    def _body(self, mask: np.ndarray, umat):
        if self.mesh.axisymmetric:
            # (z, r) mirrors the plane: the cells' winding reversed keeps their volumes positive
            cells = self.mesh.cells[mask][:, [0, 3, 2, 1, 7, 6, 5, 4, 8]]
            region = fem.RegionBiQuadraticQuad(fem.Mesh(self.mesh.points[:, ::-1].copy(), cells, "quad9"))
            fld = fem.FieldContainer([fem.FieldAxisymmetric(region, dim=2)])
        else:
            region = fem.RegionBiQuadraticQuad(fem.Mesh(self.mesh.points, self.mesh.cells[mask], "quad9"))
            fld = fem.FieldContainer([fem.FieldPlaneStrain(region, dim=2)])
        if self._first is None:
            self._first = fld
        else:
            fld.link(self._first)
        return fem.SolidBody(umat, fld), fld

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
        self._sync()
        for (_, body), fld in zip(self.bodies, self.fields, strict=True):
            r += np.asarray(body.assemble.vector(fld).todense()).ravel()
            K = K + body.assemble.matrix(fld)
        if self._perm is not None:
            r, K = r[self._perm], K.tocsr()[self._perm][:, self._perm]
        nodes = self.contact.nodes
        x = self.mesh.points[nodes] + self.u[nodes]
        f, k, normal = self.contact.forces(x, self.centre)
        dof = np.column_stack([2 * nodes, 2 * nodes + 1])
        r[dof.ravel()] -= f.ravel()
        rows = np.repeat(dof, 2, axis=1).ravel()
        cols = np.tile(dof, (1, 2)).ravel()
        K = K + sp.csr_matrix((k.ravel(), (rows, cols)), shape=(n, n))
        return r, K, f, normal

    def newton(self, tol: float | None = None, max_iter: int = 25, scale: float | None = None) -> int:
        """Equilibrium at the cap's current position; returns iterations (raises on failure).
        The residual is judged against tol x `scale` (N/mm; default: the cap's contact force)."""
        tol = self.newton_tol if tol is None else tol
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

    def platen(self, u_top: tuple[float, float], steps: int = 4) -> np.ndarray:
        """Displace the whole top surface by u_top (mm) as a bonded rigid platen would (the cap
        withdrawn), in `steps` increments; returns the platen's force on the section (N/mm),
        from the top nodes' reactions."""
        m = self.mesh
        self.centre = np.array([0.0, self.height_mm + 10.0 * self.sec.radius_mm + 10.0])  # out of reach
        fixed = self._fixed()
        fixed[m.top_nodes] = True
        self.free = np.flatnonzero(~fixed.ravel())
        for k in range(1, steps + 1):
            self.u[m.top_nodes] = np.asarray(u_top, float) * k / steps
            self.newton(scale=1e-3)
        r, _, _, _ = self._system()
        return r.reshape(-1, 2)[m.top_nodes].sum(axis=0)

    def stick_all_in_contact(self) -> None:
        """Start of the shear phase: every node in contact sticks where it is."""
        c = self.contact
        x = self.mesh.points[c.nodes] + self.u[c.nodes]
        d = x - self.centre
        gap = c.radius - np.linalg.norm(d, axis=1)
        on = gap > 0
        c.stuck[:] = on
        c.anchor[on] = d[on]  # where it is now (the tie's rest length is its penetration)

    # -------------------------------------------------------------- what crosses a node line
    def transmitted(self, z_mm: float) -> tuple[np.ndarray, np.ndarray]:
        """Nodes on the line z = z_mm (reference) and the force (n, 2) that the material below the
        line exerts on the material above it through each: the internal forces of the row of
        elements just above the line, at its nodes. At equilibrium their sum is minus the load
        on everything above (the cap's contact force): F_z and F_x cross every line whole.
        z_mm = 0 gives the base's reactions."""
        m = self.mesh
        if z_mm not in self._probes:
            nodes = m.line_nodes(z_mm)
            bottom = m.points[m.cells[:, 0], 1]  # VTK quad9: node 0 is the lower-left corner
            above = np.isclose(bottom, z_mm, atol=1e-9)
            if not above.any():
                raise ValueError(f"no element row above z = {z_mm} mm")
            probes = []
            for mask, body in self.bodies:
                sel = above & mask
                if sel.any():
                    probe, fld = self._body(sel, body.umat)
                    probes.append((probe, fld))
            self._probes[z_mm] = (nodes, probes)
        nodes, probes = self._probes[z_mm]
        f = np.zeros(self.u.size)
        self._sync()
        for probe, fld in probes:
            f += np.asarray(probe.assemble.vector(fld).todense()).ravel()
        return nodes, self._ours(f).reshape(-1, 2)[nodes]

    def layer_pressure(self, z_mm: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Across the node line z = z_mm: the nodes' reference x (mm), their normal traction
        (kPa, compressive > 0: the vertical transmitted force over each node's Simpson tributary
        length), those lengths (mm; sum(p w) is the transmitted F_z) and the lateral traction (kPa)."""
        nodes, f = self.transmitted(z_mm)
        w = self.mesh.line_weights()
        return self.mesh.points[nodes, 0], f[:, 1] / w / KPA, w, f[:, 0] / w / KPA

    def layer_mid_z(self, name: str) -> float:
        """The mid-plane node line of a layer with an even number of element rows (the Velostat
        cores), else its bottom line."""
        lo, hi = self.mesh.layer_z[name]
        z = 0.5 * (lo + hi)
        edges = self.mesh.z_edges
        return float(edges[np.argmin(np.abs(edges - z))])

    # -------------------------------------------------------------- results
    def state(self) -> dict:
        """Forces, per-layer pressure profiles, the contact and the moment balance at the current
        equilibrium. Forces on the skin (the fast model's convention): F_x along +x, F_z > 0
        compressive."""
        m = self.mesh
        _, _, f, normal = self._system()
        fx, fz = float(f[:, 0].sum()), -float(f[:, 1].sum())
        in_contact = normal > 1e-9
        x_top = m.points[m.top_nodes] + self.u[m.top_nodes]
        out = {"cap_x_mm": float(self.centre[0]), "depth_mm": float(self.height_mm + self.sec.radius_mm - self.centre[1]),
               "fx_n_per_mm": fx, "fz_n_per_mm": fz,
               "contact_from_mm": float(x_top[in_contact, 0].min()) if in_contact.any() else np.nan,
               "contact_to_mm": float(x_top[in_contact, 0].max()) if in_contact.any() else np.nan,
               "contact_x_mm": x_top[:, 0], "contact_kpa": -f[:, 1] / m.top_weights / KPA,
               "stuck_fraction": float(self.contact.stuck[in_contact].mean()) if in_contact.any() else 0.0}
        # where the load acts: its centroid along x and the height of its tangential part
        load_x = float((x_top[:, 0] * -f[:, 1]).sum() / fz) if fz else np.nan
        load_h = float((x_top[:, 1] * f[:, 0]).sum() / fx) if abs(fx) > 1e-6 * abs(fz) else float(self.height_mm)
        out.update(load_x_mm=load_x, load_height_mm=load_h)
        lines = {"superficial": self.layer_mid_z("core"), "base": 0.0}
        if "deep_core" in m.names:
            lines["deep"] = self.layer_mid_z("deep_core")
            lines["interface"] = m.layer_z["lattice"][0]
        else:
            lines["deep"] = 0.0
        for name, z in lines.items():
            x, p, w, q = self.layer_pressure(z)
            out[f"{name}_x_mm"], out[f"{name}_kpa"], out[f"{name}_w_mm"] = x, p, w
            out[f"{name}_shear_kpa"] = q
            # statics: the first moment of what crosses the line (its nodes where they are now)
            # is F_z x_load + F_x h_load + sum(z g_x): the load's moment carried down to it
            nodes, g = self.transmitted(z)
            y = m.points[nodes] + self.u[nodes]
            first = float((y[:, 0] * g[:, 1]).sum())
            expected = fz * load_x + fx * load_h + float((y[:, 1] * g[:, 0]).sum())
            out[f"{name}_first_moment"] = first
            out[f"{name}_moment_error"] = (np.nan if m.axisymmetric  # a solid of revolution has no first moment in x
                                           else (first - expected) / moment_scale(fz, fx, load_x, load_h))
        # the superficial sheet's lateral displacement (its core's mean, under the cap's start)
        out["sheet_shift_mm"] = float(self._core_shift())
        out["sheet_x_under_cap_mm"] = float(self._core_point_under(self.centre[0]))
        out["max_lattice_strain"] = float(self._max_compression())
        return out

    def _core_nodes(self) -> np.ndarray:
        return self.mesh.line_nodes(self.layer_mid_z("core"))

    def _core_shift(self) -> float:
        return float(self.u[self._core_nodes(), 0].mean())

    def _core_point_under(self, x_mm: float) -> float:
        """Reference x (the superficial sheet's own frame) of the core's mid-plane point that now
        lies at x_mm."""
        mid = self._core_nodes()
        xr = self.mesh.points[mid, 0]
        return float(np.interp(x_mm, xr + self.u[mid, 0], xr))

    def _max_compression(self) -> float:
        lo, hi = self.mesh.layer_z["lattice"]
        bottom, top = self.mesh.line_nodes(lo), self.mesh.line_nodes(hi)
        return float((self.u[bottom, 1] - self.u[top, 1]).max() / (hi - lo))
