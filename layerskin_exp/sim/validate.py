"""Physics validation of the simulated skin: each check states the physical expectation it
tests, computes the simulator's value, and compares it with a closed form or a bound.

    python -m layerskin_exp.sim.validate            # prints the table
    python -m layerskin_exp.sim.validate sim.spacer.modulus=20   # the same for another design

The checks run on the skin model itself (no protocol, no noise where they read maps), so the
table is quick (~1 min) and says what the physics does before any campaign is run.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass, replace

import numpy as np

from layerskin_exp.config import SkinConfig
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

    @property
    def passed(self) -> bool:
        return bool(self.lo <= self.value <= self.hi)


def _quiet(sim: SimConfig) -> SimConfig:
    return replace(sim, readout=replace(sim.readout, noise_counts=0.0, scan_jitter_ms=0.0))


def _model(sim: SimConfig, kind: str = "hemisphere", seed: int = 0) -> SkinModel:
    return SkinModel(sim, SKIN, kind, np.random.default_rng(seed))


def _cop(p: np.ndarray) -> np.ndarray:
    xs = SKIN.taxel_centres_mm()
    tot = p.sum()
    return np.array([p.sum(axis=0) @ xs / tot, p.sum(axis=1) @ xs / tot])


def _depth_for(model: SkinModel, fz_n: float) -> float:
    """Indentation giving normal force fz_n (from the contact tables)."""
    return float(np.interp(fz_n, model.tab.load, model.tab.delta_mm))


# ------------------------------------------------------------------------------ checks
def lateral_stiffness(sim: SimConfig) -> Check:
    """Whole bonded pad in simple shear: k = G_lattice A / h (unloaded, a light touch)."""
    m = _model(sim)
    z = -_depth_for(m, 0.05)
    m.step(0.0, np.array([0.0, 0.0, z]))
    st = m.step(0.001, np.array([0.01, 0.0, z]))
    k_sim = st.force_n[0] / st.surface_shift_mm[0]
    sp = sim.spacer
    k_closed = sp.shear_modulus_kpa * 1e-3 * sp.width**2 / sp.thickness
    return Check("lateral stiffness, light touch / closed form G A / h",
                 "a bonded elastic layer in simple shear: the pad's honeycomb shear modulus over its area and height",
                 k_sim / k_closed, 0.97, 1.15, "ratio")


def plate_on_winkler_closed_form(sim: SimConfig) -> Check:
    """The laminate solver on a linear foundation under a concentrated load against Hetenyi's
    w(0) = F / (8 sqrt(D k)) (infinite plate on a Winkler foundation)."""
    law = SpacerLaw(sim.spacer)
    d = sim.sheet.rigidity_n_mm
    k = law.e_lat_kpa * 1e-3 / law.h_mm  # N/mm^3, the open lattice's Winkler modulus
    plate = PlateOnFoundation("hemisphere", law, d, 0.0, 1.0, 2.5, 60.0, step_mm=0.05)
    a = plate._linear + __import__("scipy.sparse", fromlist=["diags"]).diags(np.where(plate.on_pad, k, 0.0))
    load = np.zeros(len(plate.x))
    force = 1.0
    load[0] = force / plate.area[0]
    w = __import__("scipy.sparse.linalg", fromlist=["spsolve"]).spsolve(a.tocsc(), load)
    w0_closed = force / (8.0 * math.sqrt(d * k))
    return Check("plate on linear foundation, w(0) / F / (8 sqrt(D k))",
                 "the laminate solver reproduces the closed form of a point-loaded plate on a Winkler foundation",
                 float(w[0]) / w0_closed, 0.95, 1.05, "ratio")


def vertical_stiffness(sim: SimConfig) -> Check:
    """Small-load stiffness of the stack against the plate-on-foundation closed form 8 sqrt(D k):
    the cover's compliance and the pad's free edge make it softer, the lattice's shear coupling
    (Pasternak) stiffer; within a factor of 1.5 either way."""
    m = _model(sim)
    tab = m.tab
    f1 = float(np.interp(0.2, tab.delta_mm, tab.load))
    f2 = float(np.interp(0.4, tab.delta_mm, tab.load))
    k_sim = (f2 - f1) / 0.2
    law = SpacerLaw(sim.spacer)
    k_closed = 8.0 * math.sqrt(sim.sheet.rigidity_n_mm * law.e_lat_kpa * 1e-3 / law.h_mm)
    return Check("vertical stiffness at light load / 8 sqrt(D k)",
                 "the sheet spreads a point load over the lattice like a plate on a foundation",
                 k_sim / k_closed, 0.67, 1.5, "ratio")


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


def preload_tangent_stiffness(sim: SimConfig) -> tuple[Check, float]:
    """Tangent vertical stiffness at the slides' 3 N preload. Films held to the Velostat by
    friction stick where the pressure lets friction carry the sandwich's shear flow and slip
    elsewhere, so the stack is stiffer than with glued films (a sandwich spreads the load
    widely) and no stiffer than with free ones: 0 = bonded bound, 1 = unbonded bound."""
    k = _tangent_at_3n(sim)
    bonded, unbonded = _bounds(sim)
    return (Check("tangent stiffness at 3 N, from bonded (0) to unbonded (1) sheet",
                  "partial sandwich action: between the glued and the free films' stacks",
                  _between(k, _tangent_at_3n(bonded), _tangent_at_3n(unbonded)), -0.02, 1.02, "fraction"), k)


def _peaks_at_3n(sim: SimConfig) -> tuple[float, float]:
    m = _model(sim)
    i = int(np.searchsorted(m.tab.delta_mm, _depth_for(m, 3.0)))
    return float(m.tab.deep_kpa[i].max()), float(m.tab.superficial_kpa[i].max())


def lattice_pressure_at_preload(sim: SimConfig) -> tuple[Check, float, float]:
    """Peak pressure in the lattice (what the deep layer reads) at the 3 N preload, between the
    bounds of the sheet's interface (0 = bonded, which spreads it over the whole pad; 1 = free
    films, under which the lattice densifies beneath the cap). Returns the check, the peak lattice
    pressure and the peak contact pressure (kPa) for the record."""
    deep, contact = _peaks_at_3n(sim)
    bonded, unbonded = _bounds(sim)
    return (Check("peak lattice pressure at 3 N, from bonded (0) to unbonded (1) sheet",
                  "the sticking films under the cap spread the load beyond what free films do",
                  _between(deep, _peaks_at_3n(bonded)[0], _peaks_at_3n(unbonded)[0]), -0.02, 1.02, "fraction"),
            deep, contact)


def moment_equilibrium(sim: SimConfig) -> Check:
    """The shear's couple about the deep plane is taken by the lattice and the indenter together."""
    plate = _solver(sim, "hemisphere")
    sol = plate.solve(_depth_for(_model(sim), 3.0))
    resp = plate.couple(sol)
    total = plate.first_moment(resp.foundation_kpa) - plate.first_moment(resp.contact_kpa)
    return Check("moment of lattice + indenter pressure per unit couple",
                 "static equilibrium: the two pressure moments add up to F_t H exactly", total, 0.98, 1.02, "")


def _slide(m: SkinModel, fz0: float, offset_mm: float, direction: float, speed=2.0, ramp_mm=None,
           shear_stop=2.0, fz_stop=6.0, travel_mm=8.0, dt=1e-3):
    """A calibration-style slide on the skin model: preload, then travel at `speed` with the
    vertical offset ramped in over `ramp_mm` (None: over the whole travel, the protocol's one
    straight move); returns (reason, records)."""
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


def friction_bound(sim: SimConfig) -> tuple[Check, Check]:
    """During stick |Fxy| <= mu_s Fz; while sliding |Fxy| ~ mu_k Fz (between the kinetic level
    less the overshoot and the static level)."""
    m = _model(sim)
    _, recs = _slide(m, 3.0, 0.0, 0.0, shear_stop=1e9, travel_mm=8.0)
    ratio = np.hypot(recs[:, 1], recs[:, 2]) / np.maximum(recs[:, 3], 1e-9)
    mu_s, mu_k = sim.cover.friction, sim.cover.kinetic
    sliding = recs[-4000:]  # the second half: steady stick-slip
    r_slide = np.hypot(sliding[:, 1], sliding[:, 2]) / sliding[:, 3]
    return (Check("max |Fxy| / (mu_s Fz) over a slide", "Coulomb: static friction bounds the shear",
                  float(ratio.max() / mu_s), 0.9, 1.0 + 1e-9, "ratio"),
            Check("mean |Fxy| / (mu_k Fz) in steady sliding", "kinetic friction carries the shear while sliding",
                  float(r_slide.mean() / mu_k), 0.9, 1.25, "ratio"))


def slide_outcomes(sim: SimConfig, n: int = 24, seed: int = 3) -> tuple[Check, Check, dict]:
    """Slides from the 3 N preload with offsets uniform in +-0.5 mm over an 8 mm straight move
    (a typical distance to the edge): most reach 2 N shear or slide at the friction bound; Fz
    stays within a few percent of the 6 N limit."""
    rng = np.random.default_rng(seed)
    reasons: dict[str, int] = {}
    fz_max = 0.0
    for _ in range(n):
        m = _model(sim)
        reason, recs = _slide(m, 3.0, float(rng.uniform(-0.5, 0.5)), float(rng.uniform(0, 2 * math.pi)))
        reasons[reason] = reasons.get(reason, 0) + 1
        fz_max = max(fz_max, float(recs[:, 3].max()))
    frac = reasons.get("shear_reached", 0) / n
    return (Check("fraction of slides stopping at 2 N shear", "vertical compliance lets most slides build 2 N",
                  frac, 0.6, 1.0, ""),
            Check("largest Fz over the slides / 6 N limit", "the normal force stops at the 6 N limit, not far past it",
                  fz_max / 6.0, 0.0, 1.05, "ratio"), reasons)


def interlayer_shift_and_height(sim: SimConfig) -> tuple[Check, Check, dict]:
    """Inter-layer CoP shift per newton of shear while sticking, and the effective height
    h = F_z dc / F_t at three preloads: of the order of the stack height (the spacer's shear
    compliance plus the moment's share in the deep layer)."""
    heights = {}
    per_n = None
    for fz0 in (1.0, 3.0, 5.0):
        m = _model(_quiet(sim))
        reason, recs = _slide(m, fz0, 0.0, 0.0, shear_stop=0.8 * fz0 * sim.cover.friction, travel_mm=6.0)
        rec = recs[-1]
        st = m.state_of(rec)
        sup, deep = m.pressure_maps([st])
        dc = _cop(sup[0])[0] - _cop(deep[0])[0]
        ft = rec[1]
        heights[fz0] = -rec[3] * dc / ft
        if fz0 == 3.0:
            per_n = -dc / ft
    return (Check("inter-layer CoP shift per N of shear at 3 N", "the spacer shears and the deep layer takes the moment",
                  per_n, 0.4, 2.0, "mm/N"),
            Check("effective height F_z dc / F_t at 3 N", "of the order of the stack height (2.9 mm) and above",
                  heights[3.0], 1.0, 8.0, "mm"), heights)


def height_rises_with_load(heights: dict) -> Check:
    """The effective height is a coupling coefficient, not the spacer's height: as the load
    grows, the contact widens and the lattice under it (not the stage-held indenter) takes a
    larger share of the shear's couple, so F_z dc / F_t rises with F_z."""
    return Check("effective height at 5 N / at 1 N", "the lattice's share of the shear's couple grows with the load",
                 heights[5.0] / heights[1.0], 1.1, 10.0, "ratio")


def _position_cv(sim: SimConfig, n_positions: int, seed: int) -> float:
    """CV of the summed counts (both layers, noise off) of a 2 N press at random positions on
    one and the same sheet."""
    rng = np.random.default_rng(seed)
    totals = []
    for _ in range(n_positions):
        xy = rng.uniform(-10.0, 10.0, 2)
        mm = _model(_quiet(sim), seed=0)  # the same sheet at every position
        st = mm.step(0.0, np.array([xy[0], xy[1], -_depth_for(mm, 2.0)]))
        counts = np.stack(mm.frames([st] * 3, np.arange(3) * 2.36e-3))[:, -1].astype(float)
        totals.append(float(np.clip(counts - mm.baseline_counts, 0, None).sum()))
    totals = np.array(totals)
    return float(totals.std(ddof=1) / totals.mean())


def response_spread(sim: SimConfig, n_positions: int = 30, seed: int = 0) -> tuple[Check, Check, dict]:
    """Taxel gains spread as configured. A contact's summed response varies from position to
    position for two reasons: where the contact sits on the taxel grid and how much of it the
    array's edge cuts off (geometry, present with uniform gains), and the gains under it. The
    second is small: the contact averages the per-crossing part, and the loaded taxels sit on
    the flat part of the column divider's response (d ln counts / d ln G = 1 / (1 + G R)), which
    compresses any gain spread. Both are returned for the record."""
    m = _model(_quiet(sim))
    g = m._gains
    taxel_cv = float(g.std() / g.mean())
    expected = math.sqrt((1 + sim.fsr.gain_cv**2) * (1 + sim.fsr.sheet_gain_cv**2) - 1)
    pos_cv = _position_cv(sim, n_positions, seed)
    uniform = replace(sim, fsr=replace(sim.fsr, gain_cv=0.0, sheet_gain_cv=0.0))
    geometric_cv = _position_cv(uniform, n_positions, seed)
    return (Check("taxel gain CV / configured (taxel and sheet parts combined)",
                  "the sheet's gains spread as configured", taxel_cv / expected, 0.8, 1.2, "ratio"),
            Check("position CV of the summed response at 2 N",
                  "set by the contact's place on the grid and the array's edge; the gains add little",
                  pos_cv, 0.02, 1.5 * expected + geometric_cv, ""),
            {"taxel_cv": taxel_cv, "position_cv": pos_cv, "position_cv_uniform_gains": geometric_cv})


def press_cop_offsets(sim: SimConfig, xs=(0.0, 4.0, 8.0)) -> dict:
    """For the record: each layer's count-CoP minus the contact position for a 3 N press (no
    shear) at x = xs mm. Whatever is not zero here enters the inter-layer shift as position,
    not shear: the deep layer's broad low-pressure tail (read through the FSR's concave response)
    and the array's edge pull its CoP towards the array centre."""
    out = {}
    for x in xs:
        m = _model(_quiet(sim))
        st = m.step(0.0, np.array([x, 0.0, -_depth_for(m, 3.0)]))
        c = np.clip(np.stack(m.frames([st] * 3, np.arange(3) * 2.36e-3))[:, -1] - m.baseline_counts, 0, None)
        out[x] = (round(float(_cop(c[0])[0] - x), 2), round(float(_cop(c[1])[0] - x), 2))
    return out


def run(sim: SimConfig | None = None) -> tuple[list[Check], dict]:
    sim = sim or SimConfig()
    c_k, k3 = preload_tangent_stiffness(sim)
    checks: list[Check] = [lateral_stiffness(sim), plate_on_winkler_closed_form(sim), vertical_stiffness(sim), c_k]
    c0, deep_peak, contact_peak = lattice_pressure_at_preload(sim)
    checks += [c0, moment_equilibrium(sim)]
    checks.extend(friction_bound(sim))
    c1, c2, reasons = slide_outcomes(sim)
    checks += [c1, c2]
    c3, c4, heights = interlayer_shift_and_height(sim)
    checks += [c3, c4, height_rises_with_load(heights)]
    c5, c6, spread = response_spread(sim)
    checks += [c5, c6]
    return checks, {"stop_reasons": reasons, "effective_height_mm_by_fz": {k: round(float(v), 3) for k, v in heights.items()},
                    "tangent_stiffness_at_3n_n_per_mm": round(k3, 2),
                    "peak_lattice_pressure_at_3n_kpa": round(deep_peak, 1),
                    "peak_lattice_pressure_over_fsr_half_saturation": round(deep_peak / sim.fsr.saturation_kpa, 2),
                    "peak_contact_pressure_at_3n_kpa": round(contact_peak, 1),
                    "press_cop_offset_mm_superficial_deep_by_x": press_cop_offsets(sim), **spread}


def table(checks: list[Check]) -> str:
    rows = [f"{'check':<62} {'value':>9} {'expected':>15}  ok  physical expectation"]
    for c in checks:
        rng = f"[{c.lo:.3g}, {c.hi:.3g}]"
        rows.append(f"{c.name:<62} {c.value:>9.3g} {rng:>15}  {'yes' if c.passed else 'NO ':<3} {c.expectation}"
                    + (f" ({c.unit})" if c.unit else ""))
    return "\n".join(rows)


def load_sim(overrides: list[str]) -> SimConfig:
    """conf/sim/default.yaml with `sim.key=value` overrides, validated by SimConfig."""
    from layerskin_exp.config import compose

    return compose("world", [o if o.startswith("sim.") else f"sim.{o}" for o in overrides]).sim


def main(argv=None) -> int:
    sim = load_sim(list(sys.argv[1:] if argv is None else argv))
    checks, extra = run(sim)
    print(table(checks))
    for k, v in extra.items():
        print(f"{k}: {v}")
    return 0 if all(c.passed for c in checks) else 1


if __name__ == "__main__":
    raise SystemExit(main())
