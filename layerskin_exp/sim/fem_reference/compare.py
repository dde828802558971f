"""The fast model beside the finite-element reference, metric by metric (see
layerskin_exp/sim/fem_reference/tolerances.yaml for what is compared, how and within what).

Both sides are brought to the same geometry class: the FEM section is a line contact, so the
fast model runs in its line-contact (rod) mode with the rod's diameter set to the hemisphere's.
Pressure fields become per-layer taxel maps (the electrode's Gauss points, as the fast model
integrates them) and then counts through the simulator's own FSR law and column readout, with
uniform gains and no noise, tared by the unloaded counts: what a researcher reads.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import yaml

from layerskin_exp import rig
from layerskin_exp.config import SkinConfig
from layerskin_exp.features import centre_of_pressure
from layerskin_exp.sim.config import SimConfig
from layerskin_exp.sim.fsr import conductance_layers
from layerskin_exp.sim.skin import SkinModel

DATA = Path(__file__).resolve().parent / "reference"
TOLERANCES = Path(__file__).resolve().parent / "tolerances.yaml"  # fixed with the reference data, not a config
SKIN = SkinConfig()
# The section models the glued (bonded) sheet only: its frictionless bound was ill-posed (see
# model.py's docstring), so the fast model's unbonded setting has no finite-element yardstick.
BOUNDS = ("bonded",)
SHEAR_RATIO = 1.0 / 3.0
# A branch that lost equilibrium before F_t / F_z reached this carries too little shear for its
# CoP signals to mean anything against the taxel pitch: its shear metrics are left out (and said).
MIN_SHEAR_RATIO = 0.1


def load_fem(bound: str, data: Path = DATA) -> dict:
    path = data / f"{bound}.npz"
    if not path.exists():
        raise FileNotFoundError(f"{path}: no FEM reference data; run `python -m layerskin_exp.sim.fem_reference`")
    with np.load(path) as z:
        return {k: z[k] for k in z.files}


def load_tolerances(path: Path = TOLERANCES) -> dict:
    return yaml.safe_load(path.read_text())


def line_sim(sim: SimConfig, bound: str) -> SimConfig:
    """The design at one film-interface bound, noise-free with uniform gains (the section's
    geometry, a rod of the hemisphere's radius, is set on the model: `line_model`)."""
    return replace(sim, sheet=replace(sim.sheet, interface=bound),
                   readout=replace(sim.readout, noise_counts=0.0, scan_jitter_ms=0.0),
                   fsr=replace(sim.fsr, gain_cv=0.0, sheet_gain_cv=0.0))


def line_model(sim: SimConfig) -> SkinModel:
    """The fast model in the section's geometry: a rod of the hemispherical indenter's radius."""
    return SkinModel(sim, SKIN, "rod", np.random.default_rng(0), contact_radius_mm=rig.INDENTER_RADIUS_MM)


def electrode_overlap(x_mm: np.ndarray, w_mm: np.ndarray, lo_mm: np.ndarray, hi_mm: np.ndarray) -> np.ndarray:
    """(len(lo), n) share of each node's force that falls on each electrode [lo, hi]: node i
    (x sorted) carries its force evenly over its tributary interval, the intervals tiling the
    line from its first node (x_mm[0] + cumsum of w_mm)."""
    bounds = np.concatenate([[x_mm[0]], x_mm[0] + np.cumsum(w_mm)])
    a, b = bounds[:-1][None, :], bounds[1:][None, :]
    inside = np.minimum(b, np.asarray(hi_mm, float)[:, None]) - np.maximum(a, np.asarray(lo_mm, float)[:, None])
    return np.clip(inside, 0.0, None) / np.asarray(w_mm, float)[None, :]


def _tensor_weights(xy_mm: np.ndarray, w_mm2: np.ndarray):
    """A plane's nodes on a tensor grid: (x nodes, y nodes, their tributary lengths, index of
    each node in the (nx, ny) grid); ValueError where the areas are not products of lengths."""
    xs, ix = np.unique(np.round(xy_mm[:, 0], 9), return_inverse=True)
    ys, iy = np.unique(np.round(xy_mm[:, 1], 9), return_inverse=True)
    grid = np.zeros((len(xs), len(ys)))
    grid[ix, iy] = w_mm2
    wx = grid.sum(axis=1) / (ys[-1] - ys[0])
    wy = grid.sum(axis=0) / (xs[-1] - xs[0])
    if len(xs) * len(ys) != len(w_mm2) or not np.allclose(np.outer(wx, wy), grid, rtol=1e-6, atol=1e-12):
        raise ValueError("the plane's node areas are not a tensor grid's (tributary length in x times in y): "
                         "pass the plane as the 3D model writes it (shear3d.Stack3D.plane)")
    return xs, ys, wx, wy, ix, iy


class Reader:
    """Pressure (kPa) -> per-layer tared counts through one skin model's FSR law and readout."""

    def __init__(self, model: SkinModel, shift_mm: float = 0.0, shift_y_mm: float = 0.0):
        self.m = model
        self.shift_mm = shift_mm  # the taxel grid's offset in the profiles' frame (alignment.py)
        self.shift_y_mm = shift_y_mm  # the same across the section (the 3D model's maps only)
        self.floor = self.counts(np.zeros((2, SKIN.n_taxels, SKIN.n_taxels)), tare=False)

    def taxel_profile(self, x_mm: np.ndarray, p_kpa: np.ndarray, w_mm: np.ndarray) -> np.ndarray:
        """(16,) electrode-mean pressure of each column from a nodal profile: node i carries
        p_i over its tributary length w_i (the intervals tile the line from its first node), so
        each electrode's mean is the force on it over its width, and a profile that carries F_z
        puts F_z on the taxels it covers. Tension (p < 0) reads as none."""
        order = np.argsort(x_mm)
        x, p, w = (np.asarray(a, float)[order] for a in (x_mm, p_kpa, w_mm))
        c, half = SKIN.taxel_centres_mm() + self.shift_mm, 0.5 * SKIN.electrode_mm
        return electrode_overlap(x, w, c - half, c + half) @ (np.clip(p, 0.0, None) * w) / SKIN.electrode_mm

    def taxel_map(self, xy_mm: np.ndarray, p_kpa: np.ndarray, w_mm2: np.ndarray, half_y: bool = True) -> np.ndarray:
        """(16, 16) electrode-mean pressure (rows y, columns x) from a plane's nodal map on a
        tensor grid (areas w = w_x w_y), read as taxel_profile reads a line in each direction.
        half_y: the nodes cover y >= 0 of a map symmetric about y = 0 (the 3D half-model);
        each electrode also gets the mirror half's force."""
        xs, ys, wx, wy, ix, iy = _tensor_weights(np.asarray(xy_mm, float), np.asarray(w_mm2, float))
        f = np.zeros((len(xs), len(ys)))
        f[ix, iy] = np.clip(np.asarray(p_kpa, float), 0.0, None) * np.asarray(w_mm2, float)
        half = 0.5 * SKIN.electrode_mm
        cx = SKIN.taxel_centres_mm() + self.shift_mm
        cy = SKIN.taxel_centres_mm() + self.shift_y_mm
        ax = electrode_overlap(xs, wx, cx - half, cx + half)
        ay = electrode_overlap(ys, wy, cy - half, cy + half)
        if half_y:
            ay = ay + electrode_overlap(ys, wy, -cy - half, -cy + half)
        return ay @ f.T @ ax.T / SKIN.electrode_mm ** 2

    def maps(self, fem: dict, sup_kpa, deep_kpa) -> np.ndarray:
        """(2, 16, 16) maps of a line contact along y: every row the same column profile; of
        the 3D half-model's planes (`superficial_xy_mm` in fem) each layer's taxel_map."""
        if "superficial_xy_mm" in fem:
            return np.stack([self.taxel_map(fem[f"{ln}_xy_mm"], p, fem[f"{ln}_w_mm2"])
                             for ln, p in (("superficial", sup_kpa), ("deep", deep_kpa))])
        n = SKIN.n_taxels
        out = np.empty((2, n, n))
        out[0] = self.taxel_profile(fem["superficial_x_mm"], sup_kpa, fem["superficial_w_mm"])[None, :]
        out[1] = self.taxel_profile(fem["deep_x_mm"], deep_kpa, fem["deep_w_mm"])[None, :]
        return out

    def counts(self, maps: np.ndarray, tare: bool = True) -> np.ndarray:
        n = SKIN.n_taxels
        m = self.m
        g = conductance_layers(m.fsr, np.asarray(maps, float)[None], m._gains)
        volts = m.readout.column_volts(g.reshape(-1, n, n)).reshape(-1, 2, n, n)
        c = m.readout.counts(volts)[0]
        return np.clip(c - self.floor, 0.0, None) if tare else c


def _cop_x(layer_counts: np.ndarray) -> float:
    return float(centre_of_pressure(layer_counts, SKIN)[0])


def _asymmetry(layer_counts: np.ndarray, about_mm: float) -> float:
    col = layer_counts.sum(axis=0)
    return float((np.sign(SKIN.taxel_centres_mm() - about_mm) * col).sum() / max(col.sum(), 1e-12))


@dataclass
class Side:
    """One side's values at one load: scalars by metric name."""

    values: dict


def at_ratio(res: dict, fz_key: str, fx_key: str, branch: float, keys) -> dict | None:
    """A branch's state at F_x / F_z = SHEAR_RATIO (linear between the states around it), with the
    press state it started from; None where the branch did not reach the ratio. res: the 3D
    check's data or a section's; fz_key, fx_key name its force columns."""
    idx = np.flatnonzero((res["phase"] == 1) & np.isclose(res["branch_depth_mm"], branch))
    start = np.flatnonzero((res["phase"] == 0) & np.isclose(res["depth_mm"], branch))
    if len(idx) == 0 or len(start) == 0:
        return None
    ratio = res[fx_key][idx] / res[fz_key][idx]
    if ratio.max() < SHEAR_RATIO:
        return None
    k = int(np.argmax(ratio >= SHEAR_RATIO))
    i0 = idx[k - 1] if k > 0 else int(start[0])
    r0 = 0.0 if k == 0 else ratio[k - 1]
    t = (SHEAR_RATIO - r0) / (ratio[k] - r0)
    out = {key: (1 - t) * np.asarray(res[key][i0], float) + t * np.asarray(res[key][idx[k]], float) for key in keys}
    out["start"] = int(start[0])
    return out


def _fem_at_ratio(fem: dict, branch: float) -> dict:
    """The FEM branch's state at F_t / F_z = SHEAR_RATIO (linear between the two states around
    it; the branch's last state, at the ratio it reached, where it stopped short of it) and the
    press state it started from."""
    phase, bd = fem["phase"], fem["branch_depth_mm"]
    idx = np.flatnonzero((phase == 1) & np.isclose(bd, branch))
    start = int(np.flatnonzero((phase == 0) & np.isclose(fem["depth_mm"], branch))[0])
    if len(idx) == 0:
        raise ValueError(f"FEM branch from {branch} mm has no sheared state")
    ratio = fem["fx_n_per_mm"][idx] / fem["fz_n_per_mm"][idx]
    if ratio.max() >= SHEAR_RATIO:
        k = int(np.argmax(ratio >= SHEAR_RATIO))
        r0 = 0.0 if k == 0 else ratio[k - 1]
        t, target = (SHEAR_RATIO - r0) / (ratio[k] - r0), SHEAR_RATIO
    else:
        k, t, target = len(idx) - 1, 1.0, float(ratio[-1])
    i1 = idx[k]
    i0 = idx[k - 1] if k > 0 else start
    out = {"ratio": target}
    for key in ("cap_x_mm", "fx_n_per_mm", "fz_n_per_mm", "sheet_x_under_cap_mm", "superficial_kpa", "deep_kpa"):
        out[key] = (1 - t) * fem[key][i0].astype(float) + t * fem[key][i1].astype(float)
    out["start"] = start
    return out


def fem_side(fem: dict, reader: Reader, branches) -> list[dict]:
    rows = []
    for b in branches:
        s = _fem_at_ratio(fem, b)
        st = s["start"]
        deep_map = reader.maps(fem, fem["superficial_kpa"][st], fem["deep_kpa"][st])
        press = reader.counts(deep_map)
        sheared = reader.counts(reader.maps(fem, s["superficial_kpa"], s["deep_kpa"]))
        fz, fx = float(fem["fz_n_per_mm"][st]), float(s["fx_n_per_mm"])
        dc = _cop_x(sheared[0]) - _cop_x(sheared[1])
        under = float(s["sheet_x_under_cap_mm"])
        rows.append({
            "depth_mm": float(fem["depth_mm"][st]), "fz_n_per_mm": fz, "shear_ratio": s["ratio"],
            "contact_width_mm": float(fem["contact_to_mm"][st] - fem["contact_from_mm"][st]),
            "peak_superficial_kpa": float(fem["superficial_kpa"][st].max()),
            "peak_deep_taxel_kpa": float(deep_map[1].max()),
            "tangential_stiffness": fx / float(s["cap_x_mm"]),
            "sheet_share_of_travel": (float(s["cap_x_mm"]) - under) / float(s["cap_x_mm"]),
            "interlayer_shift_counts_mm": dc,
            "effective_height_counts": -float(s["fz_n_per_mm"]) * dc / fx,
            "deep_cop_counts_mm": _cop_x(sheared[1]) - _cop_x(press[1]),
            "superficial_offset_counts_mm": _cop_x(sheared[0]) - under,
            "superficial_asymmetry_counts": _asymmetry(sheared[0], under),
            # for the record, not compared: where the deep layer's force (not its counts) moved
            "deep_cop_force_mm": _force_cop(fem["deep_x_mm"], s["deep_kpa"], fem["deep_w_mm"])
            - _force_cop(fem["deep_x_mm"], fem["deep_kpa"][st], fem["deep_w_mm"]),
        })
    return rows


def _force_cop(x_mm, p_kpa, w_mm) -> float:
    f = np.asarray(p_kpa, float) * np.asarray(w_mm, float)
    return float((np.asarray(x_mm, float) * f).sum() / f.sum())


def fast_side(model: SkinModel, reader: Reader, loads_n_per_mm, ratios=None) -> list[dict]:
    """The fast model (rod mode) at the FEM's normal line loads, sheared while sticking to
    F_t / F_z = the FEM's ratio at each (SHEAR_RATIO where it reached it)."""
    tab = model.tab
    half = model.sim.spacer.width_mm / 2
    length = 2.0 * half  # the line along y crosses the whole pad
    rows = []
    fresh = model.mech_state()  # unloaded, nothing stuck
    ratios = [SHEAR_RATIO] * len(loads_n_per_mm) if ratios is None else ratios
    for load, target in zip(loads_n_per_mm, ratios, strict=True):
        delta = float(np.interp(load, tab.load, tab.delta_mm))
        model.restore_mech_state(fresh)
        rec0 = model.step_many(np.array([0.0]), np.array([[0.0, 0.0, -delta]]), np.array([np.pi / 2]))[0]
        # stick: F_t = k_t u with u = the cap's travel; step to the travel that gives the ratio
        xs = np.linspace(0.0, 3.0, 601)[1:]
        recs = model.step_many(1e-3 * np.arange(1, len(xs) + 1), np.column_stack([xs, np.zeros_like(xs), -delta * np.ones_like(xs)]),
                               np.full(len(xs), np.pi / 2))
        ratio = recs[:, 1] / recs[:, 3]
        k = int(np.argmax(ratio >= target))
        rec = recs[k]
        st0, st = model.state_of(rec0), model.state_of(rec)
        maps0 = np.stack(model.pressure_maps([st0]))[:, 0]
        maps1 = np.stack(model.pressure_maps([st]))[:, 0]
        press, sheared = reader.counts(maps0), reader.counts(maps1)
        fz, fx = float(rec[3]) / length, float(rec[1]) / length
        dc = _cop_x(sheared[0]) - _cop_x(sheared[1])
        under = float(rec[6])  # contact point in the superficial frame (x - u)
        rows.append({
            "depth_mm": delta, "fz_n_per_mm": fz, "shear_ratio": float(ratio[k]),
            "contact_width_mm": 2.0 * float(np.interp(delta, tab.delta_mm, tab.contact_halfwidth_mm)),
            "peak_superficial_kpa": float(np.interp(delta, tab.delta_mm, tab.superficial_kpa.max(axis=1))),
            "peak_deep_taxel_kpa": float(maps0[1].max()),
            "tangential_stiffness": fx / float(xs[k]),
            "sheet_share_of_travel": float(rec[9]) / float(xs[k]),
            "interlayer_shift_counts_mm": dc,
            "effective_height_counts": -float(rec[3]) * dc / float(rec[1]),
            "deep_cop_counts_mm": _cop_x(sheared[1]) - _cop_x(press[1]),
            "superficial_offset_counts_mm": _cop_x(sheared[0]) - under,
            "superficial_asymmetry_counts": _asymmetry(sheared[0], under),
            "deep_cop_force_mm": float(centre_of_pressure(maps1[1], SKIN)[0] - centre_of_pressure(maps0[1], SKIN)[0]),
        })
    return rows


def band(tol: dict, metric: str, fem_value: float) -> tuple[str, float, float]:
    """(kind, lo, hi) of a metric: its width in the tolerances, widened by the reference's
    measured discretisation error where `discretisation:` lists one (a relative error e turns
    [lo, hi] into [lo / (1 + e), hi (1 + e)]; a position's error in mm adds to its limit; a
    dimensionless difference's relative error adds e |FEM|)."""
    widen = (tol.get("discretisation") or {}).get(metric, 0.0)
    if metric in tol["ratio"]:
        lo, hi = tol["ratio"][metric]
        return "ratio", lo / (1.0 + widen), hi * (1.0 + widen)
    limit = tol["difference"][metric]
    extra = widen if metric.endswith("_mm") else widen * abs(fem_value)
    return "difference", -(limit + extra), limit + extra


@dataclass
class Comparison:
    bound: str
    metric: str
    load: str
    fem: float
    fast: float
    kind: str  # "ratio" | "difference"
    lo: float
    hi: float

    @property
    def value(self) -> float:
        return self.fast / self.fem if self.kind == "ratio" else self.fast - self.fem

    @property
    def passed(self) -> bool:
        v = self.value
        return bool(np.isfinite(v) and self.lo <= v <= self.hi)


def compare(sim: SimConfig, data: Path = DATA, tolerances: dict | None = None,
            model_hook=None, bounds=None) -> tuple[list[Comparison], dict]:
    """All comparisons, both bounds. model_hook(sim) -> sim may alter the fast model's design
    (the tests inject errors through it). Returns the rows and, for the record, each side's
    values at each load, and the default (friction-held) fast model's beside them."""
    tol = tolerances or load_tolerances()
    rows, record = [], {}
    for bound in bounds or BOUNDS:
        fem = load_fem(bound, data)
        branches = sorted(set(np.round(fem["branch_depth_mm"][fem["phase"] == 1], 6)))
        fsim = line_sim(sim, bound)
        if model_hook is not None:
            fsim = model_hook(fsim)
        model = line_model(fsim)
        reader = Reader(model)
        f_rows = fem_side(fem, reader, branches)
        loads = [r["fz_n_per_mm"] for r in f_rows]
        s_rows = fast_side(model, reader, loads, [r["shear_ratio"] for r in f_rows])
        record[bound] = {"fem": f_rows, "fast": s_rows}
        # vertical stiffness at the FEM's own depths
        press = np.flatnonzero(fem["phase"] == 0)
        for j in press:
            d = float(fem["depth_mm"][j])
            kind, lo, hi = band(tol, "line_load_at_depth", float(fem["fz_n_per_mm"][j]))
            rows.append(Comparison(bound, "line_load_at_depth", f"depth {d:.2f} mm", float(fem["fz_n_per_mm"][j]),
                                   float(np.interp(d, model.tab.delta_mm, model.tab.load)), kind, lo, hi))
        sheared = [(fr, sr) for fr, sr in zip(f_rows, s_rows, strict=True) if fr["shear_ratio"] >= MIN_SHEAR_RATIO]
        record[bound]["shear_left_out"] = [{"fz_n_per_mm": fr["fz_n_per_mm"], "shear_ratio": fr["shear_ratio"]}
                                           for fr in f_rows if fr["shear_ratio"] < MIN_SHEAR_RATIO]

        def at(fr):
            return f"{fr['fz_n_per_mm']:.3f} N/mm" + ("" if fr["shear_ratio"] >= SHEAR_RATIO - 1e-9
                                                       else f", Ft/Fz {fr['shear_ratio']:.2f}")

        def add(metric, label, fem_value, fast_value, bound=bound):
            kind, lo, hi = band(tol, metric, fem_value)
            rows.append(Comparison(bound, metric, label, fem_value, fast_value, kind, lo, hi))

        for metric in ("contact_width", "peak_superficial_kpa", "peak_deep_taxel_kpa"):
            key = metric if metric in f_rows[0] else metric + "_mm"
            for fr, sr in zip(f_rows, s_rows, strict=True):
                add(metric, f"{fr['fz_n_per_mm']:.3f} N/mm", fr[key], sr[key])
        for metric in ("tangential_stiffness", "effective_height_counts"):
            for fr, sr in sheared:
                add(metric, at(fr), fr[metric], sr[metric])
        if len(sheared) >= 2:
            (f0, s0), (f1, s1) = sheared[0], sheared[-1]
            add("effective_height_rise", "highest / lowest load",
                f1["effective_height_counts"] / f0["effective_height_counts"],
                s1["effective_height_counts"] / s0["effective_height_counts"])
        for metric in tol["difference"]:
            for fr, sr in sheared:
                add(metric, at(fr), fr[metric], sr[metric])
    if bounds is not None:
        return rows, record
    # the default design (films held by friction) beside both bounds, for the record
    model = line_model(line_sim(sim, sim.sheet.interface))
    record["default_" + sim.sheet.interface] = fast_side(model, Reader(model),
                                                         [r["fz_n_per_mm"] for r in record["bonded"]["fem"]],
                                                         [r["shear_ratio"] for r in record["bonded"]["fem"]])
    return rows, record


def table(rows: list[Comparison]) -> str:
    out = [f"{'bound':<9} {'metric':<30} {'at':<22} {'FEM':>9} {'fast':>9} {'fast vs FEM':>12} {'allowed':>16}  ok"]
    for r in rows:
        rel = f"{r.value:.3g}" + (" x" if r.kind == "ratio" else " d")
        out.append(f"{r.bound:<9} {r.metric:<30} {r.load:<22} {r.fem:>9.4g} {r.fast:>9.4g} {rel:>12} "
                   f"{'[' + f'{r.lo:.3g}, {r.hi:.3g}' + ']':>16}  {'yes' if r.passed else 'NO'}")
    return "\n".join(out)


def main() -> int:
    from layerskin_exp.sim.config import load_sim

    rows, record = compare(load_sim([]))
    print(table(rows))
    print(json.dumps(record, indent=1, default=float))
    return 0
