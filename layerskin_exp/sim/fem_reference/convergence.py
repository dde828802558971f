"""Mesh refinement of the finite-element reference: every quantity the comparison reads, on the
coarse, default and fine meshes (`python -m layerskin_exp.sim.fem_reference --refinement`).

A quantity is converged when it changes by less than REL_TOL (positions: by less than POS_TOL_MM)
between the two finest meshes. One that is not carries its measured change into the comparison
as a discretisation error: layerskin_exp/sim/fem_reference/tolerances.yaml's `discretisation:` widens that metric's
band by it, and `uncovered` lists every quantity that is neither converged nor so covered.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from layerskin_exp.sim.config import SimConfig
from layerskin_exp.sim.fem_reference import compare as fc

DATA = fc.DATA
CONVERGENCE = DATA / "convergence.json"
LEVELS = ("coarse", "default", "fine")
REL_TOL = 0.05
POS_TOL_MM = 0.05
# compared quantities that are positions (judged by their change in mm, not relative)
POSITIONS = ("interlayer_shift_counts_mm", "deep_cop_counts_mm", "superficial_offset_counts_mm")


# a row key of compare.fem_side -> the comparison's metric name, where they differ
METRIC = {"contact_width_mm": "contact_width"}


def judge(before: float, after: float, position: bool) -> dict:
    """A quantity's change between two meshes: in mm for a position, else relative to `before`;
    converged below POS_TOL_MM or REL_TOL."""
    if position:
        change, limit, kind = after - before, POS_TOL_MM, "mm"
    else:
        change, limit, kind = (after - before) / abs(before), REL_TOL, "relative"
    return {"change": round(float(change), 6), "kind": kind, "converged": bool(np.isfinite(change) and abs(change) < limit)}


def level_path(level: str, data: Path = DATA) -> Path:
    return data / ("" if level == "default" else f"refinement/{level}")


def quantities(fem: dict, reader: fc.Reader) -> dict:
    """metric -> {load label: value}, keyed by the press depth each value belongs to (the same
    on every mesh, where the line loads differ)."""
    out: dict = {}
    press = np.flatnonzero(fem["phase"] == 0)
    for j in press:
        out.setdefault("line_load_at_depth", {})[f"{fem['depth_mm'][j]:.2f} mm"] = float(fem["fz_n_per_mm"][j])
    branches = sorted(set(np.round(fem["branch_depth_mm"][fem["phase"] == 1], 6)))
    for row in fc.fem_side(fem, reader, branches):
        label = f"{row['depth_mm']:.2f} mm"
        for k, v in row.items():
            if k not in ("depth_mm", "fz_n_per_mm", "shear_ratio"):
                out.setdefault(METRIC.get(k, k), {})[label] = float(v)
    return out


def study(sim: SimConfig, data: Path = DATA) -> dict:
    model = fc.line_model(fc.line_sim(sim, "bonded"))
    reader = fc.Reader(model)
    per_level = {lv: quantities(fc.load_fem("bonded", level_path(lv, data)), reader) for lv in LEVELS}
    return {"rel_tol": REL_TOL, "pos_tol_mm": POS_TOL_MM, "quantities": _rows(per_level, "default", "fine")}


def _rows(runs: dict, before: str, after: str) -> dict:
    """"metric @ load" -> each run's value of it (a column per run) and its change from run
    `before` to run `after` (`judge`); the quantities are `before`'s."""
    rows = {}
    for metric, by_load in runs[before].items():
        for load in by_load:
            vals = {name: float(q.get(metric, {}).get(load, np.nan)) for name, q in runs.items()}
            rows[f"{metric} @ {load}"] = {"metric": metric, "load": load, **{k: round(v, 6) for k, v in vals.items()},
                                          **judge(vals[before], vals[after], metric in POSITIONS)}
    return rows


def cover_compressibility(sim: SimConfig, nus, data: Path = DATA) -> dict:
    """Each compared quantity of the committed section (the cover at the spacer's Poisson ratio)
    beside the same section with the cover at each of `nus` (cover_poisson/nu_*.npz), and the
    change, judged as a mesh step is (`judge`)."""
    reader = fc.Reader(fc.line_model(fc.line_sim(sim, "bonded")))
    base = quantities(fc.load_fem("bonded", data), reader)
    out = {}
    for nu in nus:
        with np.load(data / "cover_poisson" / f"nu_{nu:.4f}.npz") as z:
            alt = quantities({k: z[k] for k in z.files}, reader)
        out[f"{nu:.4f}"] = _rows({"committed": base, "cover_nu": alt}, "committed", "cover_nu")
    return {"committed_cover_nu": float(sim.spacer.poisson), "rel_tol": REL_TOL, "pos_tol_mm": POS_TOL_MM, "by_cover_nu": out}


def write_convergence(sim: SimConfig, data: Path = DATA) -> str:
    res = study(sim, data)
    (data / "convergence.json").write_text(json.dumps(res, indent=1))
    return table(res)


def load(path: Path = CONVERGENCE) -> dict:
    return json.loads(path.read_text())


def discretisation_error(conv: dict) -> dict:
    """metric -> the largest |change| between the two finest meshes over its loads (relative, or
    mm for positions)."""
    out: dict = {}
    for q in conv["quantities"].values():
        out[q["metric"]] = max(out.get(q["metric"], 0.0), abs(q["change"]))
    return out


def uncovered(conv: dict, tolerances: dict) -> list[str]:
    """Quantities that neither converged nor have their change covered by the tolerances'
    `discretisation:` widening of their metric."""
    widen = tolerances.get("discretisation", {}) or {}
    compared = set(tolerances["ratio"]) | set(tolerances["difference"])
    return [name for name, q in conv["quantities"].items() if q["metric"] in compared
            and not q["converged"] and not abs(q["change"]) <= widen.get(q["metric"], -1.0)]


def table(conv: dict) -> str:
    out = [f"{'quantity':<48} {'coarse':>10} {'default':>10} {'fine':>10} {'change':>10}  converged"]
    for name, q in conv["quantities"].items():
        ch = f"{q['change']:+.3f} mm" if q["kind"] == "mm" else f"{100 * q['change']:+.1f} %"
        out.append(f"{name:<48} {q['coarse']:>10.4g} {q['default']:>10.4g} {q['fine']:>10.4g} {ch:>10}  "
                   f"{'yes' if q['converged'] else 'NO'}")
    return "\n".join(out)
