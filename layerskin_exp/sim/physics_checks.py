"""Physics validation of the simulated skin: each check states the physical expectation it
tests and the physical error it catches, computes the simulator's value, and compares it with a
closed form, a bound, or the finite-element reference (`layerskin_exp.sim.fem_reference`).

The command that prints them is `python -m layerskin_exp.sim.validate` (kept apart so that its
--help and a refused command line load none of the physics).

The checks run on the skin model itself (no protocol). A check never encodes a study outcome or
a protocol outcome (stop-reason fractions, force maxima): those are printed below the table as
results, with the inter-layer shift, effective heights and position spread read from counts
after the readout. The FEM comparison's tolerances are fixed in layerskin_exp/sim/fem_reference/tolerances.yaml.
Every check takes `model_sim`, the design the simulated side is built from (default: `sim`): the
tests inject an error there (a perturbed parameter, a disabled mechanism) and see the check fail.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sparse
import scipy.sparse.linalg as sparse_linalg

from layerskin_exp.config import SkinConfig
from layerskin_exp.features import centre_of_pressure
from layerskin_exp.sim import mechanics as mk
from layerskin_exp.sim.config import SimConfig
from layerskin_exp.sim.contact import _solver
from layerskin_exp.sim.laminate import PlateOnFoundation
from layerskin_exp.sim.skin import SkinModel
from layerskin_exp.sim.spacer import SpacerLaw

SKIN = SkinConfig()


@dataclass
class Check:
    name: str
    expectation: str
    value: float
    lo: float
    hi: float
    unit: str = ""
    catches: str = ""  # the physical error that moves the value out of [lo, hi]

    @property
    def passed(self) -> bool:
        return bool(np.isfinite(self.value) and self.lo <= self.value <= self.hi)


def _quiet(sim: SimConfig) -> SimConfig:
    return replace(sim, readout=replace(sim.readout, noise_counts=0.0, scan_jitter_ms=0.0))


def _model(sim: SimConfig, kind: str = "hemisphere", seed: int = 0) -> SkinModel:
    return SkinModel(sim, SKIN, kind, np.random.default_rng(seed))


def _cop_x(maps: np.ndarray) -> float:
    return float(centre_of_pressure(np.asarray(maps, float), SKIN)[0])


def _depth_for(model: SkinModel, fz_n: float) -> float:
    """Indentation giving normal force fz_n (from the contact tables)."""
    return float(np.interp(fz_n, model.tab.load, model.tab.delta_mm))


# The calibration slide's stops as the protocol runs them by default (slide.shear_stop_n,
# safety.max_normal_force_n of conf/force_calibration.yaml): the protocols' schema sits above the
# core, so they are written here and tests/sim/test_validate.py holds them to the composed config.
SLIDE_SHEAR_STOP_N = 2.0
NORMAL_FORCE_LIMIT_N = 6.0


def protocol_stops() -> tuple[float, float]:
    """(shear stop N, normal force limit N) of the calibration slide (the protocol's defaults)."""
    return SLIDE_SHEAR_STOP_N, NORMAL_FORCE_LIMIT_N


# ------------------------------------------------------------------------------ checks
def lateral_stiffness(sim: SimConfig, model_sim: SimConfig | None = None) -> Check:
    """Whole bonded pad in simple shear: k = G_lattice A / h (unloaded, a light touch)."""
    m = _model(model_sim or sim)
    z = -_depth_for(m, 0.05)
    m.step(0.0, np.array([0.0, 0.0, z]))
    st = m.step(0.001, np.array([0.01, 0.0, z]))
    k_sim = st.force_n[0] / st.surface_shift_mm[0]
    sp = sim.spacer
    k_closed = sp.shear_modulus_kpa * 1e-3 * sp.width_mm**2 / sp.thickness_mm
    return Check("lateral stiffness, light touch / closed form G A / h",
                 "a bonded elastic layer in simple shear: the pad's honeycomb shear modulus over its area and height",
                 k_sim / k_closed, 0.97, 1.15, "ratio",
                 "the pad's shear stiffness not wired to the honeycomb's (e.g. the solid's modulus, or a wrong wall fraction)")


def plate_on_winkler_closed_form(sim: SimConfig, model_sim: SimConfig | None = None) -> Check:
    """The laminate solver on a linear foundation under a concentrated load against Hetenyi's
    w(0) = F / (8 sqrt(D k)) (infinite plate on a Winkler foundation)."""
    ms = model_sim or sim
    law = SpacerLaw(ms.spacer)
    d_model = ms.sheet.rigidity_n_mm
    plate = PlateOnFoundation("hemisphere", law, d_model, 0.0, 1.0, 2.5, 60.0, step_mm=0.05)
    k_model = law.e_lat_kpa * 1e-3 / law.h_mm
    a = plate._linear + sparse.diags(np.where(plate.on_pad, k_model, 0.0))
    load = np.zeros(len(plate.x))
    force = 1.0
    load[0] = force / plate.area[0]
    w = sparse_linalg.spsolve(a.tocsc(), load)
    k = SpacerLaw(sim.spacer).e_lat_kpa * 1e-3 / sim.spacer.thickness_mm  # N/mm^3, the open lattice's Winkler modulus
    w0_closed = force / (8.0 * math.sqrt(sim.sheet.rigidity_n_mm * k))
    return Check("plate on linear foundation, w(0) / F / (8 sqrt(D k))",
                 "the laminate solver reproduces the closed form of a point-loaded plate on a Winkler foundation",
                 float(w[0]) / w0_closed, 0.95, 1.05, "ratio",
                 "a wrong bending operator or rigidity in the laminate solver (a sheet 20 % too stiff or soft)")


def vertical_stiffness(sim: SimConfig, model_sim: SimConfig | None = None) -> Check:
    """Small-load stiffness of the stack against the plate-on-foundation closed form 8 sqrt(D k):
    the cover's compliance and the pad's free edge make it softer, the lattice's shear coupling
    (Pasternak) stiffer; within a factor of 1.5 either way. The closed form is the small-deflection
    plate's, so a design whose sheet stretches (`sim.sheet.large_deflection`) is judged in that
    limit, its membrane off: from 0.2 to 0.4 mm the friction-held films already stretch (their
    membrane, C = 2.3 kN/mm, outweighs their bending over the cap's width), which no linear plate
    models; that the membrane vanishes at a light touch is tested with the solver
    (tests/sim/test_large_deflection.py)."""
    m = _model(_small_deflection(model_sim or sim))
    tab = m.tab
    f1 = float(np.interp(0.2, tab.delta_mm, tab.load))
    f2 = float(np.interp(0.4, tab.delta_mm, tab.load))
    k_sim = (f2 - f1) / 0.2
    law = SpacerLaw(sim.spacer)
    k_closed = 8.0 * math.sqrt(sim.sheet.rigidity_n_mm * law.e_lat_kpa * 1e-3 / law.h_mm)
    return Check("vertical stiffness at light load / 8 sqrt(D k)",
                 "the sheet spreads a point load over the lattice like a plate on a foundation",
                 k_sim / k_closed, 0.67, 1.5, "ratio",
                 "a sheet that does not spread the load (rigidity lost) or a lattice modulus off by more than ~2x")


def _small_deflection(sim: SimConfig) -> SimConfig:
    return replace(sim, sheet=replace(sim.sheet, large_deflection=False, wrinkling=False))


def _bounds(sim: SimConfig) -> tuple[SimConfig, SimConfig]:
    """The same design with the sheet's films glued (bonded) and free (unbonded)."""
    return (replace(sim, sheet=replace(sim.sheet, interface="bonded")),
            replace(sim, sheet=replace(sim.sheet, interface="unbonded")))


def _between(value: float, bound_a: float, bound_b: float) -> float:
    """Where value lies from bound_a (0) to bound_b (1)."""
    return 0.0 if bound_b == bound_a else (value - bound_a) / (bound_b - bound_a)


def _tangent_at_3n(sim: SimConfig) -> float:
    m = _model(sim)
    d3 = _depth_for(m, 3.0)
    return float(np.interp(d3 + 0.05, m.tab.delta_mm, m.tab.load) - np.interp(d3 - 0.05, m.tab.delta_mm, m.tab.load)) / 0.1


def _peaks_at_3n(sim: SimConfig) -> tuple[float, float]:
    m = _model(sim)
    i = int(np.searchsorted(m.tab.delta_mm, _depth_for(m, 3.0)))
    return float(m.tab.deep_kpa[i].max()), float(m.tab.superficial_kpa[i].max())


def interface_record(sim: SimConfig) -> dict:
    """For the record: the friction-held films' tangent stiffness and peak lattice pressure at
    3 N, placed between the glued (0) and free (1) films' values."""
    bonded, unbonded = _bounds(sim)
    k = _tangent_at_3n(sim)
    deep, contact = _peaks_at_3n(sim)
    return {"tangent_stiffness_at_3n_n_per_mm": round(k, 2),
            "tangent_stiffness_between_bonded_0_unbonded_1": round(_between(k, _tangent_at_3n(bonded), _tangent_at_3n(unbonded)), 3),
            "peak_lattice_pressure_at_3n_kpa": round(deep, 1),
            "peak_lattice_pressure_between_bonded_0_unbonded_1": round(_between(deep, _peaks_at_3n(bonded)[0], _peaks_at_3n(unbonded)[0]), 3),
            "peak_lattice_pressure_over_fsr_half_saturation": round(deep / sim.fsr.saturation_kpa, 2),
            "peak_contact_pressure_at_3n_kpa": round(contact, 1)}


def membrane_record(sim: SimConfig, fz_n: float = 3.0) -> dict:
    """For the record: the large-deflection sheet's hoop membrane force at a 3 N press against the
    compressive membrane force at which a plate on a Winkler foundation wrinkles, 2 sqrt(D k)
    (D the sheet's rigidity there, k the open lattice's E / h; Hetenyi's infinite plate), for the
    design's films and glued.

    Beyond a few mm from the cap the stretched sheet's rim is pulled inwards and its hoop force
    turns compressive; where it passes that threshold a real sheet wrinkles and carries (almost) no
    hoop compression (a tension field). The axisymmetric plate, and the 3D model's merged sheet on
    its coarse outer mesh, stay smooth and keep it, so the membrane's spreading of a deep press is
    an upper bound where the threshold is passed. (`sim.sheet.wrinkling` lets the fast sheet
    wrinkle there; this record is of the smooth one, whichever the design has.)"""
    out = {}
    for label, design in (("films", sim), ("glued", _bounds(sim)[0])):
        ld = replace(design, sheet=replace(design.sheet, large_deflection=True, wrinkling=False))  # the smooth sheet
        plate = _solver(ld, "hemisphere")
        sol = plate.solve(_depth_for(_model(ld), fz_n))
        n_r, n_t = sol.membrane_n_per_mm
        mid = 0.5 * (plate.x[:-1] + plate.x[1:])
        d = np.interp(mid, plate.x, sol.rigidity_n_mm) if sol.rigidity_n_mm is not None else ld.sheet.rigidity_n_mm
        k = plate.law.e_lat_kpa * 1e-3 / plate.law.h_mm
        over = -n_t > 2.0 * np.sqrt(d * k)
        out[label] = {"hoop_min_n_per_mm": round(float(n_t.min()), 3),
                      "wrinkling_threshold_n_per_mm": round(float(2.0 * np.sqrt(np.median(d) * k)), 3),
                      # that wrinkle's wavelength, 2 pi (D / k)^(1/4): a hoop wave must fit the rim's circumference
                      "wrinkle_wavelength_mm": round(float(2.0 * math.pi * (np.median(d) / k) ** 0.25), 1),
                      "over_threshold_from_to_mm": [round(float(mid[over].min()), 1), round(float(mid[over].max()), 1)]
                      if over.any() else None}
    return {"membrane_hoop_at_3n_large_deflection": out}


def moment_equilibrium(sim: SimConfig, model_sim: SimConfig | None = None) -> Check:
    """The shear's couple about the deep plane is taken by the lattice and the indenter together:
    the cover's lever under the contact (the hemisphere at 3 N) and the lattice's at the pad's
    sides (the straight side the fast model places, per unit length)."""
    ms = model_sim or sim
    plate = _solver(ms, "hemisphere")
    sol = plate.solve(_depth_for(_model(ms), 3.0))
    lattice_mm = ms.spacer.thickness_mm - float(np.maximum(sol.w_mm, 0.0)[0])
    share = lattice_mm / (ms.cover.thickness_mm + ms.fsr.layer_thickness_mm + lattice_mm)
    resp = plate.couple(sol, share)
    side = _solver(ms, "rod")
    edge = side.edge_couple()
    total = (plate.first_moment(resp.foundation_kpa) - plate.first_moment(resp.contact_kpa)
             + share * (side.first_moment(edge.foundation_kpa) - side.first_moment(edge.contact_kpa)))
    return Check("moment of lattice + indenter pressure per unit couple",
                 "static equilibrium: the two pressure moments add up to F_t H exactly", total, 0.98, 1.02, "",
                 "a couple response out of equilibrium (the indenter's or the lattice's share lost or double-counted)")


def _slide(m: SkinModel, fz0: float, offset_mm: float, direction: float, speed=2.0, ramp_mm=None,
           shear_stop=None, fz_stop=None, travel_mm=8.0, dt=1e-3):
    """A calibration-style slide on the skin model: preload, then travel at `speed` with the
    vertical offset ramped in over `ramp_mm` (None: over the whole travel, the protocol's one
    straight move); stops at the protocol's shear stop and force limit unless given; returns
    (reason, records)."""
    stop_shear_n, limit_n = protocol_stops()
    shear_stop = stop_shear_n if shear_stop is None else shear_stop
    fz_stop = limit_n if fz_stop is None else fz_stop
    ramp_mm = travel_mm if ramp_mm is None else ramp_mm
    z0 = -_depth_for(m, fz0)
    m.step(0.0, np.array([0.0, 0.0, z0]))
    e = np.array([math.cos(direction), math.sin(direction)])
    n = int(travel_mm / speed / dt)
    s = np.arange(1, n + 1) * speed * dt
    xyz = np.column_stack([s * e[0], s * e[1], z0 - offset_mm * np.minimum(s / ramp_mm, 1.0)])
    recs = m.step_many(np.arange(1, n + 1) * dt, xyz, np.zeros(n))
    shear = np.hypot(recs[:, 1], recs[:, 2])
    fz = recs[:, 3]
    stop_shear = np.flatnonzero(shear >= shear_stop)
    stop_fz = np.flatnonzero(fz >= fz_stop)
    first = {"shear_reached": stop_shear[0] if len(stop_shear) else n,
             "force_limit": stop_fz[0] if len(stop_fz) else n}
    reason = min(first, key=first.get)
    if first[reason] >= n:
        return "skin_edge", recs
    return reason, recs[:first[reason] + 1]


# The friction checks' slide starts from a light preload so that the contact slides within the
# slide's 8 mm: from 3 N the stack's shear over that travel stays below mu_s F_z (the cap travels
# about 1/3 N per mm there) and a slide that never slips cannot judge the friction law.
FRICTION_PRELOAD_N = 0.5


def friction_bound(sim: SimConfig, model_sim: SimConfig | None = None) -> tuple[Check, Check]:
    """During stick |Fxy| <= mu_s Fz; while sliding |Fxy| ~ mu_k Fz (between the kinetic level
    less the overshoot and the static level). A slide that never slips fails both (NaN)."""
    m = _model(model_sim or sim)
    _, recs = _slide(m, FRICTION_PRELOAD_N, 0.0, 0.0, shear_stop=1e9, fz_stop=1e9, travel_mm=8.0)
    ratio = np.hypot(recs[:, 1], recs[:, 2]) / np.maximum(recs[:, 3], 1e-9)
    mu_s, mu_k = sim.cover.friction, sim.cover.kinetic
    # sliding: from the first slip on (the stick phase before it builds the shear up from zero)
    first = np.flatnonzero(recs[:, mk.S_SLIPPING] > 0)
    if len(first):
        sliding = recs[first[0]:]
        held, carried = float(ratio.max() / mu_s), float((np.hypot(sliding[:, 1], sliding[:, 2]) / sliding[:, 3]).mean() / mu_k)
    else:
        held = carried = float("nan")
    return (Check("max |Fxy| / (mu_s Fz) over a slide", "Coulomb: static friction bounds the shear",
                  held, 0.9, 1.0 + 1e-9, "ratio",
                  "a stick-slip law that lets the shear exceed static friction (or never reaches it)"),
            Check("mean |Fxy| / (mu_k Fz) in steady sliding", "kinetic friction carries the shear while sliding",
                  carried, 0.9, 1.25, "ratio",
                  "a sliding contact that does not carry the kinetic friction force"))


def slide_record(sim: SimConfig, n: int = 24, seed: int = 3) -> dict:
    """For the record, not a check: slides from the 3 N preload with offsets uniform in
    +-0.5 mm over an 8 mm straight move, stopped by the protocol's thresholds: why they stopped
    and the largest normal force (protocol outcomes, which the physics must not be tuned to)."""
    rng = np.random.default_rng(seed)
    reasons: dict[str, int] = {}
    fz_max = 0.0
    for _ in range(n):
        m = _model(sim)
        reason, recs = _slide(m, 3.0, float(rng.uniform(-0.5, 0.5)), float(rng.uniform(0, 2 * math.pi)))
        reasons[reason] = reasons.get(reason, 0) + 1
        fz_max = max(fz_max, float(recs[:, 3].max()))
    return {"slide_stop_reasons": reasons, "slide_largest_fz_n": round(fz_max, 2)}


def _tared_counts(m: SkinModel, states) -> np.ndarray:
    """(N, 2, 16, 16) counts after the readout (steady: three frames of each state), less the
    unloaded sheet's."""
    out = []
    for st in states:
        c = np.stack(m.frames([st] * 3, np.arange(3) * 2.36e-3))[:, -1].astype(float)
        out.append(c)
    return np.clip(np.array(out) - m._idle_counts[None], 0.0, None)


def shift_and_height_record(sim: SimConfig) -> dict:
    """For the record: the hemisphere's inter-layer count-CoP shift per newton of shear while
    sticking at 3 N, and the effective height h = F_z dc / F_t at 1, 3 and 5 N, from counts
    after the readout (noise off)."""
    heights, per_n = {}, None
    for fz0 in (1.0, 3.0, 5.0):
        m = _model(_quiet(sim))
        _, recs = _slide(m, fz0, 0.0, 0.0, shear_stop=0.8 * fz0 * sim.cover.friction, fz_stop=1e9, travel_mm=6.0)
        rec = recs[-1]
        c = _tared_counts(m, [m.state_of(rec)])[0]
        dc = _cop_x(c[0]) - _cop_x(c[1])
        heights[fz0] = round(float(-rec[3] * dc / rec[1]), 3)
        if fz0 == 3.0:
            per_n = round(float(-dc / rec[1]), 3)
    return {"interlayer_shift_counts_mm_per_n_at_3n": per_n, "effective_height_counts_mm_by_fz": heights}


def _position_cv(sim: SimConfig, n_positions: int, seed: int) -> float:
    """CV of the summed counts (both layers, noise off) of a 2 N press at random positions on
    one and the same sheet."""
    rng = np.random.default_rng(seed)
    totals = []
    for _ in range(n_positions):
        xy = rng.uniform(-10.0, 10.0, 2)
        mm = _model(_quiet(sim), seed=0)  # the same sheet at every position
        st = mm.step(0.0, np.array([xy[0], xy[1], -_depth_for(mm, 2.0)]))
        totals.append(float(_tared_counts(mm, [st]).sum()))
    totals = np.array(totals)
    return float(totals.std(ddof=1) / totals.mean())


def gain_spread(sim: SimConfig, model_sim: SimConfig | None = None) -> Check:
    """Taxel gains spread as configured (taxel and sheet parts combined)."""
    m = _model(_quiet(model_sim or sim))
    g = m._gains
    taxel_cv = float(g.std() / g.mean())
    expected = math.sqrt((1 + sim.fsr.gain_cv**2) * (1 + sim.fsr.sheet_gain_cv**2) - 1)
    return Check("taxel gain CV / configured (taxel and sheet parts combined)",
                 "the sheet's gains spread as configured", taxel_cv / expected, 0.8, 1.2, "ratio",
                 "a gain generator that drops or double-counts the taxel or the sheet part of the spread")


def spread_record(sim: SimConfig, n_positions: int = 30, seed: int = 0) -> dict:
    """For the record, not a check: the position-to-position spread of a 2 N press's summed
    counts, with the configured gains and with uniform ones (geometry alone)."""
    uniform = replace(sim, fsr=replace(sim.fsr, gain_cv=0.0, sheet_gain_cv=0.0))
    return {"position_cv": round(_position_cv(sim, n_positions, seed), 4),
            "position_cv_uniform_gains": round(_position_cv(uniform, n_positions, seed), 4)}


def press_cop_offsets(sim: SimConfig, xs=(0.0, 4.0, 8.0)) -> dict:
    """For the record: each layer's count-CoP minus the contact position for a 3 N press (no
    shear) at x = xs mm. Whatever is not zero here enters the inter-layer shift as position,
    not shear: the deep layer's broad low-pressure tail (read through the FSR's concave response)
    and the array's edge pull its CoP towards the array centre."""
    out = {}
    for x in xs:
        m = _model(_quiet(sim))
        st = m.step(0.0, np.array([x, 0.0, -_depth_for(m, 3.0)]))
        c = _tared_counts(m, [st])[0]
        out[x] = (round(_cop_x(c[0]) - x, 2), round(_cop_x(c[1]) - x, 2))
    return out


# FEM comparison rows: what physical error in the fast model each metric catches
FEM_CATCHES = {
    "line_load_at_depth": "a stack too stiff or too soft in compression (lattice law, sheet spreading, cover)",
    "contact_width": "a sheet that spreads the cap's load too little or too much (its rigidity, large deflection)",
    "peak_superficial_kpa": "a wrong contact pressure under the cap (the superficial FSR's saturation depends on it)",
    "peak_deep_taxel_kpa": "a wrong spread of the load onto the deep sheet through the lattice cells",
    "tangential_stiffness": "a wrong shear compliance of the stack (spacer shear, cover shear)",
    "effective_height_counts": "a wrong coupling of shear into the layers' CoP difference, as the sensor reads it",
    "effective_height_rise": "a wrong change of that coupling with load",
    "sheet_share_of_travel": "a cover rigid (or too compliant) in shear: how much of the cap's travel the sheet follows",
    "interlayer_shift_counts_mm": "a wrong inter-layer shift under shear, read through FSR and readout",
    "deep_cop_counts_mm": "a wrong movement of the deep layer's CoP under shear (the moment's share in the lattice)",
    "superficial_offset_counts_mm": "no (or wrong) flank load: the superficial map's shift against the contact under shear",
    "superficial_asymmetry_counts": "no (or wrong) direction signal in the superficial map under shear",
    "depth_at_load": "a stack too stiff or too soft in compression (lattice law, sheet spreading, cover)",
    "contact_radius": "a sheet that spreads the cap's load too little or too much (its rigidity, large deflection)",
    "superficial_cop_counts_mm": "a wrong cover compliance or couple: how far the superficial map follows the cap",
    "sheet_travel_mm": "a wrong split of the cap's travel between the cover and the lattice in shear",
}


def fem_checks(sim: SimConfig, model_sim: SimConfig | None = None, bounds=None) -> tuple[list[Check], dict]:
    """The fast model against the FEM reference, within layerskin_exp/sim/fem_reference/tolerances.yaml;
    the count-CoP shear rows on their means over the alignments of cap, walls and taxels
    (fem_reference.alignment.gate)."""
    from layerskin_exp.sim.fem_reference import alignment
    from layerskin_exp.sim.fem_reference import compare as fc

    hook = None
    if model_sim is not None:
        def hook(fsim, _ms=model_sim):  # the injected design, in the comparison's geometry and bound
            return replace(fc.line_sim(_ms, fsim.sheet.interface))
    rows, record = alignment.gate(sim, model_hook=hook, bounds=bounds)
    checks = []
    for r in rows:
        unit = "fast / FEM" if r.kind == "ratio" else "fast - FEM"
        checks.append(Check(f"FEM {r.bound}: {r.metric} at {r.load} (FEM {r.fem:.3g}, fast {r.fast:.3g})",
                            "the fast model agrees with the finite-element section", r.value, r.lo, r.hi, unit,
                            FEM_CATCHES.get(r.metric, "")))
    return checks, record


def yardstick_checks(sim: SimConfig, model_sim: SimConfig | None = None) -> tuple[list[Check], dict]:
    """The fast hemisphere against the 3D half-model of the study's geometry, within
    tolerances.yaml's `yardstick3d:` (fem_reference.yardstick3d): the rows validate exits on."""
    from layerskin_exp.sim.fem_reference import yardstick3d

    hook = None if model_sim is None else (lambda _s, _ms=model_sim: _ms)
    rows, record = yardstick3d.rows(sim, model_hook=hook)
    checks = []
    for r in rows:
        unit = "fast / 3D" if r.kind == "ratio" else "fast - 3D"
        checks.append(Check(f"3D: {r.metric} at {r.load} (3D {r.fem:.3g}, fast {r.fast:.3g})",
                            "the fast model agrees with the 3D model of the study's geometry", r.value, r.lo, r.hi,
                            unit, FEM_CATCHES.get(r.metric, "")))
    return checks, record


def run(sim: SimConfig | None = None, fem: bool = True) -> tuple[list[Check], dict]:
    """The checks validate exits on (closed forms, bounds, the 3D yardstick) and, for the record,
    what else it prints: the plane-strain section's rows (`section_checks`, diagnostics that gate
    nothing: what the section's walls and plane strain do to each row)."""
    sim = sim or SimConfig()
    checks: list[Check] = [lateral_stiffness(sim), plate_on_winkler_closed_form(sim), vertical_stiffness(sim),
                           moment_equilibrium(sim), *friction_bound(sim), gain_spread(sim)]
    extra: dict = {}
    if fem:
        rows3d, record3d = yardstick_checks(sim)
        checks += rows3d
        extra["yardstick3d_record"] = record3d
        fem_rows, fem_record = fem_checks(sim)
        extra["section_checks"] = fem_rows
        extra["fem_record"] = fem_record
    extra.update(interface_record(sim))
    extra.update(membrane_record(sim))
    extra.update(slide_record(sim))
    extra.update(shift_and_height_record(sim))
    extra.update(spread_record(sim))
    extra["press_cop_offset_mm_superficial_deep_by_x"] = press_cop_offsets(sim)
    return checks, extra


def table(checks: list[Check]) -> str:
    rows = [f"{'check':<62} {'value':>9} {'expected':>15}  ok  physical expectation / error it catches"]
    for c in checks:
        rng = f"[{c.lo:.3g}, {c.hi:.3g}]"
        rows.append(f"{c.name:<62} {c.value:>9.3g} {rng:>15}  {'yes' if c.passed else 'NO ':<3} {c.expectation}"
                    + (f" ({c.unit})" if c.unit else "") + (f"; catches: {c.catches}" if c.catches else ""))
    return "\n".join(rows)
