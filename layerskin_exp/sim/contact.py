"""Contact of a rigid indenter (hemisphere or rod) with the thin soft stack, as tables.

Hertz does not apply: the stack is far thinner than the contact is wide, and the indenter
presses a stiff laminate (the cover and the superficial FSR sheet) that rests on a soft
lattice. The laminate spreads the load over several millimetres of lattice as a plate on a
nonlinear foundation (`laminate.PlateOnFoundation`); the lattice densifies under the contact
only when the sheet's bending can no longer hand the load outwards. Everything is solved once
per design, as tables over the indentation depth delta:

- hemisphere: axisymmetric radial profiles p(delta, r);
- rod: line-contact profiles p(delta, d) across the axis, per unit length along it.

Per row: the normal force (or line load); the pressure the superficial layer feels and the
deep layer feels (the lattice's pressure); their first-order change per unit couple of the shear
about the deep plane through the cover's part of the lever, which acts under the contact and of
which the indenter takes a share (`laminate.PlateOnFoundation.couple`); the lattice's extra
tangential and torsional stiffness under the contact; the friction radius; the height of the
cover above the deep sensing plane and the lattice's height under the contact. The lattice's part
of the couple and the columns' lean (F_z u: the columns under the contact lean by the sheet's
travel, their thrust joins the lattice's shear) are handed over the whole pad by the sheet and
end at the pad's sides, half on the sheet, which tilts, half straight on the deep sheet
(`laminate.PlateOnFoundation.edge_couple`): one table across a side, placed at the pad's four
sides by the frame pipeline wherever the contact is. The moment balance holds for the whole deep
pressure, not for what the sensor reads. Lengths mm, pressures kPa, forces N.

What the superficial layer feels. Its Velostat core lies between the sheet's two electrode films,
which carry the sheet's bending (the core is soft). The sheet is loaded on its top by the contact
(through the cover) and on its bottom by the lattice's reaction; the difference is what the
films' bending shear hands along. Across the core that shear is uniform in depth (the films carry
the membrane forces), so the core's normal stress runs linearly from the top load to the bottom
one, and its mean, what the FSR reads, is half of each. With two films alike (crossed strips, the
sheet taken as isotropic, see `laminate.sheet_rigidity_n_mm`) the same half holds where the
films slip and bend on their own: each carries half the bending, the core passes the rest. So
the superficial layer reads the mean of the contact pressure and the lattice's pressure.
Reading the contact alone misses the lattice's load outside the contact and its shift under shear.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import i0e

from layerskin_exp import rig
from layerskin_exp.sim.config import SimConfig
from layerskin_exp.sim.laminate import (
    FrictionInterface,
    PlateOnFoundation,
    cover_shear_stiffness_n_per_mm3,
    cover_stiffness_n_per_mm3,
    pad_radius_mm,
)
from layerskin_exp.sim.spacer import SpacerLaw

KPA_MM2_TO_N = 1e-3
_PLATE_STEP_MM = 0.05  # grid of the laminate solve (the cover's contact edge spans several steps)


@dataclass
class ContactTables:
    """Precomputed contact response of one indenter on one stack design.

    Row k of every (n_delta, ...) table is indentation delta_mm[k] (uniform grid).
    `load` is the normal force (hemisphere, N) or line load (rod, N/mm).
    Profiles are sampled on the uniform grid `dist_mm` (radius or signed distance to the axis).
    """

    kind: str
    delta_mm: np.ndarray  # (n_delta,)
    load: np.ndarray  # (n_delta,) N or N/mm
    dist_mm: np.ndarray  # (n_dist,)
    superficial_kpa: np.ndarray  # (n_delta, n_dist) the mean of the contact's and the lattice's (see above)
    deep_kpa: np.ndarray  # (n_delta, n_dist) after spreading through the spacer
    shear_extra: np.ndarray  # (n_delta,) contact's extra tangential stiffness, N/mm (rod: per mm)
    torsion_extra: np.ndarray  # (n_delta,) hemisphere: extra torsional stiffness N mm/rad
    friction_radius_mm: np.ndarray  # (n_delta,) int p r dA / int p dA (hemisphere)
    contact_halfwidth_mm: np.ndarray  # (n_delta,) contact radius / half-width of the Winkler zone
    superficial_couple_kpa: np.ndarray  # (n_delta, n_dist) its change per unit couple
    deep_couple_kpa: np.ndarray  # (n_delta, n_dist) lattice-pressure change per unit couple
    height_mm: np.ndarray  # (n_delta,) height of the cover surface above the deep sensing plane
    lattice_compression_mm: np.ndarray  # (n_delta,) the lattice's compression under the contact
    # the cover between cap and sheet (laminate.PlateOnFoundation.flank): its tangential
    # stiffness, the traction over the contact and what the flank pressure on the sunk cap's
    # slope adds to it once the sheet's response and the slope's change are counted, N/mm
    # (rod: per mm); its torsional stiffness, traction only: hemisphere N mm/rad, rod the
    # traction's N/mm per mm^2 of contact, to be taken with the line's second moment
    cover_shear: np.ndarray  # (n_delta,)
    cover_torsion: np.ndarray  # (n_delta,)
    cover_n_per_mm3: np.ndarray  # (n_delta,) the cover's compression stiffness each row was solved with
    # the sheet's top load, the contact pressure spread through the cover, and its change per unit
    # couple: the superficial core's other half (the frame pipeline adds half the lattice's
    # pressure with its cell pattern; `superficial_kpa` is that mean with the smooth lattice)
    cover_kpa: np.ndarray  # (n_delta, n_dist)
    cover_couple_kpa: np.ndarray  # (n_delta, n_dist)
    # the lattice's route (laminate.PlateOnFoundation.edge_couple): the couple it carries, the
    # shear's F_t h_L and the columns' lean F_z u (the sheet's travel u leans the columns under the
    # contact; their thrust F_z u / h joins the lattice's shear), is handed over the whole pad by
    # the in-plane-stiff sheet and ends at the pad's sides, wherever the contact is. Per unit
    # couple per mm along a side, across it on `edge_dist_mm` (the pad's centre at 0, its sides at
    # +-half its width): the deep sheet's pressure (the lattice's base) and the lattice's top
    # (what the superficial core reads half of), both odd; the same for every indentation
    edge_dist_mm: np.ndarray  # (n_edge,)
    edge_deep_kpa: np.ndarray  # (n_edge,)
    edge_top_kpa: np.ndarray  # (n_edge,)
    lattice_height_mm: np.ndarray  # (n_delta,) the lattice's height under the contact: its lever
    # how far inside each side its load's moment acts (mm; the edge tables' own:
    # PlateOnFoundation.side_inset_mm, negative where the solid rim's couple outweighs its net load)
    side_inset_mm: float

    @property
    def d_delta(self) -> float:
        return float(self.delta_mm[1] - self.delta_mm[0])



def _radial_gauss_matrix(r_out: np.ndarray, r_in: np.ndarray, dr_in: float, sigma: float) -> np.ndarray:
    """Matrix M with (f * G_sigma)(r_out) = M @ f(r_in) for axisymmetric f (2D Gaussian blur)."""
    s2 = sigma * sigma
    ro, ri = r_out[:, None], r_in[None, :]
    # exp(-(r^2 + r'^2)/2s^2) I0(r r'/s^2) written with the scaled Bessel for stability
    return (ri / s2) * np.exp(-((ro - ri) ** 2) / (2 * s2)) * i0e(ro * ri / s2) * dr_in


def _line_gauss_matrix(d_out: np.ndarray, d_in: np.ndarray, dd_in: float, sigma: float) -> np.ndarray:
    return np.exp(-((d_out[:, None] - d_in[None, :]) ** 2) / (2 * sigma**2)) / (math.sqrt(2 * math.pi) * sigma) * dd_in


def contact_radius_mm(kind: str) -> float:
    """The rig's indenter radius (hemisphere) or rod radius (rod), mm."""
    return rig.INDENTER_RADIUS_MM if kind == "hemisphere" else rig.ROD_DIAMETER_MM / 2


def _solver(sim: SimConfig, kind: str, radius_mm: float | None = None) -> PlateOnFoundation:
    """The laminate-on-lattice model of one design (see `laminate`). `radius_mm` replaces the
    rig's indenter/rod radius only for reference comparisons (e.g. a 2-D section's cylinder)."""
    law = SpacerLaw(sim.spacer)
    radius = contact_radius_mm(kind) if radius_mm is None else radius_mm
    g_p = sim.spacer.shear_modulus_kpa * KPA_MM2_TO_N * sim.spacer.thickness_mm / 3.0  # Vlasov: G h / 3
    # the cover's stiffness at a first contact of the cap's own scale; build_tables sets it per
    # indentation from the contact's size (contact_confinement_mm)
    k_c = cover_stiffness_n_per_mm3(sim.cover.modulus_kpa, sim.cover.thickness_mm, radius)
    sheet = sim.sheet
    interface = None
    if sheet.interface == "friction":
        interface = FrictionInterface(sheet.rigidity_n_mm, sheet.sandwich_rigidity_n_mm, sheet.film_separation_mm,
                                      sheet.interface_friction)
    # the cover's silicone is taken as the spacer's (conf/sim/default.yaml), its Poisson ratio too
    g_c = cover_shear_stiffness_n_per_mm3(sim.cover.modulus_kpa, sim.spacer.poisson, sim.cover.thickness_mm)
    return PlateOnFoundation(kind, law, sheet.rigidity_n_mm, g_p, k_c, radius,
                             pad_radius_mm(kind, sim.spacer.width_mm), step_mm=_PLATE_STEP_MM, interface=interface,
                             cover_shear_n_per_mm3=g_c, rim_mm=sim.spacer.rim_width_mm,
                             membrane_n_per_mm=sheet.membrane_n_per_mm if sheet.large_deflection else 0.0,
                             wrinkle_n_per_mm=wrinkle_n_per_mm(sim) if sheet.wrinkling else None)


def wrinkle_n_per_mm(sim: SimConfig) -> float:
    """The membrane compression at which the sheet on the open lattice wrinkles, 2 sqrt(D k) (a plate
    on a Winkler foundation, Hetenyi): D the sheet's rigidity as its films hold (slipping films:
    their own), k the open lattice's E / h."""
    law = SpacerLaw(sim.spacer)
    return 2.0 * math.sqrt(sim.sheet.rigidity_n_mm * law.e_lat_kpa * KPA_MM2_TO_N / law.h_mm)


def contact_confinement_mm(kind: str, x_mm: np.ndarray, weight: np.ndarray, contact_kpa: np.ndarray) -> float:
    """Half-width of the region over which the cap squeezes the cover (its Gent & Lindley
    shape factor's L), from the contact pressure's spread: a disc of radius a under a
    Hertz-like p ~ sqrt(1 - r^2/a^2) has <r^2> = 2 a^2 / 5, a strip of half-width a has
    <x^2> = a^2 / 4. A pressure moment, not the last touching grid point, so that it changes
    smoothly with the indentation."""
    total = float(contact_kpa @ weight)
    if total <= 0.0:
        return 0.0
    m2 = float((contact_kpa * x_mm**2) @ weight) / total
    return math.sqrt(2.5 * m2) if kind == "hemisphere" else 2.0 * math.sqrt(m2)


def build_tables(sim: SimConfig, kind: str, radius_mm: float | None = None) -> ContactTables:
    """Solve the laminate on its lattice for a grid of indentation depths (see `laminate`).

    The cover is squeezed only under the contact, so its compression stiffness (an
    incompressible bonded layer: 1 + 2 S^2, S = L / 2t) takes L from the contact's size. Each
    row uses the size found at the row before (rows are a small step of indentation apart; the
    first starts from the cap's chord at that depth)."""
    if kind not in ("hemisphere", "rod"):
        raise ValueError(f"indenter={kind!r}: must be 'hemisphere' or 'rod'")
    law = SpacerLaw(sim.spacer)
    plate = _solver(sim, kind, radius_mm)
    radius = plate.radius
    h = sim.spacer.thickness_mm
    delta_max = min(0.99 * radius, 0.97 * h)
    n_delta = sim.contact.table_points
    delta = np.linspace(0.0, delta_max, n_delta)
    x = plate.x
    n_x = len(x)
    contact = np.zeros((n_delta, n_x))
    found = np.zeros((n_delta, n_x))
    contact1 = np.zeros((n_delta, n_x))
    found1 = np.zeros((n_delta, n_x))
    comp = np.zeros((n_delta, n_x))
    load = np.zeros(n_delta)
    cover_shear = np.zeros(n_delta)
    cover_kc = np.zeros(n_delta)
    cover_torsion = np.zeros(n_delta)
    w = eta = u = None
    centre = int(np.argmin(np.abs(x)))
    cover_e, cover_t = sim.cover.modulus_kpa, sim.cover.thickness_mm
    reach_mm = None
    for k, dl in enumerate(delta):
        if dl <= 0.0:
            continue
        if reach_mm is None:  # the cap's chord at this depth
            reach_mm = math.sqrt(max(2.0 * radius * dl - dl * dl, 0.0))
        plate.k_cover = cover_kc[k] = cover_stiffness_n_per_mm3(cover_e, cover_t, reach_mm)
        sol = plate.solve(float(dl), w, eta_start=eta, u_start=u)
        w, eta, u = sol.w_mm, sol.composite, sol.u_mm
        contact[k], found[k], comp[k] = sol.contact_kpa, sol.foundation_kpa, np.maximum(w, 0.0)
        reach_mm = max(contact_confinement_mm(kind, x, plate.area, sol.contact_kpa), 0.5 * plate.step)
        load[k] = plate.load(sol)
        # the couple's levers: the cover and sheet above the lattice, the lattice's own height
        # under the contact; their sum is the row's height H (below). The cover's route here, the
        # lattice's at the pad's sides (edge tables, below)
        lattice_mm = h - comp[k, centre]
        resp = plate.couple(sol, lattice_mm / (sim.cover.thickness_mm + sim.fsr.layer_thickness_mm + lattice_mm))
        contact1[k], found1[k] = resp.contact_kpa, resp.foundation_kpa
        # the cap moving relative to the sheet: its stiffness (`PlateOnFoundation.flank`). Its
        # response is the solved state moved with the cap (first moment F_z per unit travel:
        # tests/sim/test_cover_shear.py), which the frame pipeline carries by placing the patterns
        # about the cap's point in the sheet's frame; adding it to the couple's tables counted that
        # travel twice, so it is not solved here
        cover_shear[k] = plate.traction_stiffness(sol)
        touching = sol.contact_kpa > 0.0
        g_c = plate.cover_shear_n_per_mm3
        cover_torsion[k] = g_c * float((x**2 * touching) @ plate.area) if kind == "hemisphere" \
            else g_c * float(touching @ plate.area)
    # what each layer's Velostat feels: the superficial core the mean of the contact pressure,
    # spread over the cover's thickness, and the lattice's (see the module's docstring); the deep
    # core the lattice's pressure on its sheet; the lattice's spread over half a sheet's thickness
    sigma_s = sim.cover.thickness_mm
    sigma_d = 0.5 * sim.fsr.layer_thickness_mm
    # tabulated to just beyond the plate's edge (the equal-area disc), where the lattice ends
    reach = min(float(np.abs(x).max()), pad_radius_mm(kind, sim.spacer.width_mm) + 1.0)
    if kind == "hemisphere":
        dist = np.linspace(0.0, reach, 801)
        blur_s = _radial_gauss_matrix(dist, x, plate.step, sigma_s)
        blur_d = _radial_gauss_matrix(dist, x, plate.step, sigma_d)
        weight = plate.area
    else:
        dist = np.linspace(-reach, reach, 961)
        blur_s = _line_gauss_matrix(dist, x, plate.step, sigma_s)
        blur_d = _line_gauss_matrix(dist, x, plate.step, sigma_d)
        weight = plate.area
    deep = found @ blur_d.T  # signed: where the sheet lifts, the bonded lattice pulls (the FSR reads 0)
    cover = contact @ blur_s.T
    superficial = 0.5 * (cover + deep)
    deep1 = found1 @ blur_d.T
    cover1 = contact1 @ blur_s.T
    superficial1 = 0.5 * (cover1 + deep1)
    edge_dist, edge_deep, edge_top, side_inset = _edge_tables(sim, sigma_d)
    k_extra = law.shear_stiffness_kpa_per_mm(comp) - law.shear_stiffness_kpa_per_mm(0.0)
    k_extra = np.where(comp > 0, k_extra, 0.0)
    shear_extra = k_extra @ weight * KPA_MM2_TO_N
    torsion_extra = (k_extra * x[None, :] ** 2) @ weight * KPA_MM2_TO_N if kind == "hemisphere" else np.zeros(n_delta)
    with np.errstate(invalid="ignore", divide="ignore"):
        fr = (contact * np.abs(x)[None, :]) @ weight / (contact @ weight)
    fr = np.nan_to_num(fr)
    halfwidth = np.array([np.abs(x[row > 0]).max() if (row > 0).any() else 0.0 for row in contact])
    height = sim.cover.thickness_mm + sim.fsr.layer_thickness_mm + h - comp[:, centre]
    return ContactTables(kind, delta, load, dist, superficial, deep, shear_extra, torsion_extra, fr,
                         halfwidth, superficial1, deep1, height, comp[:, centre].copy(), cover_shear, cover_torsion,
                         cover_kc, cover, cover1, edge_dist, edge_deep, edge_top, h - comp[:, centre], side_inset)


def _edge_tables(sim: SimConfig, sigma_d: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """The lattice's route across the pad (`ContactTables.edge_deep_kpa`): a straight side, per
    unit couple per mm along it, on the unloaded lattice (`PlateOnFoundation.edge_couple`);
    blurred like the deep profiles (half a sheet's thickness); and its side load's inset."""
    plate = _solver(sim, "rod")
    resp = plate.edge_couple()
    reach = plate.pad_radius + 1.0
    dist = np.linspace(-reach, reach, 961)
    blur = _line_gauss_matrix(dist, plate.x, plate.step, sigma_d)
    return (dist, blur @ resp.foundation_kpa, blur @ (resp.foundation_kpa - 2.0 * resp.direct_kpa),
            plate.side_inset_mm())
