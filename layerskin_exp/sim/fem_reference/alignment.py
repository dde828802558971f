"""The count-CoP shear signals averaged over where the contact sits on the walls and the taxels.

The section's walls (2 mm pitch) carry the lattice's load about ten times the cells' level, and
the taxels (1.5 mm pitch) sample it; at the one alignment of the committed section (the cap on the
centre wall, between two taxels) the walls decide the sign of every count-CoP shear signal
(reference/homogenisation.json: homogenised inside the same solid rim, the inter-layer shift is
-0.15 / -0.23 mm where the cells give +0.24 / +0.53). A campaign presses at a hundred positions,
every alignment. So each signal is also taken here over a grid of alignments:

- the FEM: the cap pressed in at ALIGN_X0_MM from the centre wall (`python -m
  layerskin_exp.sim.fem_reference --alignments`, reference/alignment/), each read with the
  taxel grid placed so that the cap starts at ALIGN_TAXEL_MM from a taxel's centre;
- the fast model (line contact, as in `compare`): the rod pressed in at ALIGN_TAXEL_MM from a
  taxel's centre.

Each signal is the sheared state's change from its own press (at an alignment other than the
symmetric one the press alone has a count offset), at F_t / F_z = SHEAR_RATIO; the same loads
and ratios as `compare`. `python -m layerskin_exp.sim.fem_reference.alignment` prints the table:
each side's mean and range over its alignments, and the homogenised section's (taxel alignments
only: it has no walls).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from layerskin_exp.sim.fem_reference.compare import (
    BOUNDS,
    DATA,
    MIN_SHEAR_RATIO,
    SHEAR_RATIO,
    SKIN,
    Comparison,
    Reader,
    _asymmetry,
    _cop_x,
    _fem_at_ratio,
    at_ratio,
    band,
    compare,
    line_model,
    line_sim,
    load_fem,
    load_tolerances,
)

# where the cap presses in, from the wall under the pad's centre (cell pitch 2 mm): on a wall and a
# quarter, half and three quarters of a cell away (the __main__'s --alignments runs)
ALIGN_X0_MM = (0.0, 0.5, 1.0, 1.5)
ALIGN_TAXEL_MM = (0.0, 0.375, 0.75, 1.125)  # the cap from a taxel's centre (the pitch is 1.5 mm)
SIGNALS = ("interlayer_shift_counts_mm", "effective_height_counts", "deep_cop_counts_mm",
           "superficial_offset_counts_mm", "superficial_asymmetry_counts")


def signals(press: np.ndarray, sheared: np.ndarray, fz: float, fx: float, under_mm: float, start_mm: float) -> dict:
    """Shear signals of one sheared state from its press, counts (2, 16, 16) in the taxel grid's
    frame: under_mm, the superficial sheet's point under the cap, start_mm, where the cap pressed."""
    dc = (_cop_x(sheared[0]) - _cop_x(sheared[1])) - (_cop_x(press[0]) - _cop_x(press[1]))
    return {"interlayer_shift_counts_mm": dc,
            "effective_height_counts": -fz * dc / fx,
            "deep_cop_counts_mm": _cop_x(sheared[1]) - _cop_x(press[1]),
            # the superficial layer's own count-CoP travel (not in SIGNALS: the 3D check's row)
            "superficial_cop_counts_mm": _cop_x(sheared[0]) - _cop_x(press[0]),
            "superficial_offset_counts_mm": (_cop_x(sheared[0]) - under_mm) - (_cop_x(press[0]) - start_mm),
            "superficial_asymmetry_counts": _asymmetry(sheared[0], under_mm) - _asymmetry(press[0], start_mm)}


def _centre() -> float:
    """The taxel centre nearest the array's middle (the grid's coordinates)."""
    c = SKIN.taxel_centres_mm()
    return float(c[np.argmin(np.abs(c))])


def fem_signals(fem: dict, model, taxel_mm: float) -> dict:
    """{branch depth: signals} of one FEM run, read with the cap starting taxel_mm from a taxel's
    centre."""
    x0 = float(fem.get("cap_start_mm", 0.0))
    # a taxel's centre (the grid's, moved by the shift) at x0 - taxel_mm: the cap starts there + taxel_mm
    reader = Reader(model, shift_mm=x0 - taxel_mm - _centre())
    out = {}
    for b in sorted(set(np.round(fem["branch_depth_mm"][fem["phase"] == 1], 6))):
        s = _fem_at_ratio(fem, b)
        st = s["start"]
        press = reader.counts(reader.maps(fem, fem["superficial_kpa"][st], fem["deep_kpa"][st]))
        sheared = reader.counts(reader.maps(fem, s["superficial_kpa"], s["deep_kpa"]))
        out[float(b)] = {**signals(press, sheared, float(s["fz_n_per_mm"]), float(s["fx_n_per_mm"]),
                                   float(s["sheet_x_under_cap_mm"]) - reader.shift_mm, x0 - reader.shift_mm),
                         "fz_n_per_mm": float(fem["fz_n_per_mm"][st]), "shear_ratio": s["ratio"]}
    return out


def fem3d_signals(res: dict, model, taxel_mm: float, taxel_y_mm: float) -> dict:
    """{branch depth: signals} of the 3D half-model (shear3d.npz, the cap pressed at x = y = 0),
    read with the cap starting taxel_mm from a taxel's centre along x and taxel_y_mm across;
    branches that did not reach F_t / F_z = SHEAR_RATIO are left out."""
    reader = Reader(model, shift_mm=-taxel_mm - _centre(), shift_y_mm=-taxel_y_mm - _centre())
    keys = ("cap_x_mm", "fx_n", "fz_n", "sheet_x_under_cap_mm", "superficial_kpa", "deep_kpa")
    out = {}
    for b in sorted(set(np.round(res["branch_depth_mm"][res["phase"] == 1], 6))):
        s = at_ratio(res, "fz_n", "fx_n", b, keys)
        if s is None:
            continue
        st = s["start"]
        press = reader.counts(reader.maps(res, res["superficial_kpa"][st], res["deep_kpa"][st]))
        sheared = reader.counts(reader.maps(res, s["superficial_kpa"], s["deep_kpa"]))
        out[float(b)] = {**signals(press, sheared, float(s["fz_n"]), float(s["fx_n"]),
                                   float(s["sheet_x_under_cap_mm"]) - reader.shift_mm, -reader.shift_mm),
                         "fz_n": float(res["fz_n"][st]), "shear_ratio": SHEAR_RATIO}
    return out


def fast_signals(model, fresh, reader: Reader, load_n_per_mm: float, ratio: float, taxel_mm: float) -> dict:
    """The fast model's rod pressed to a line load at taxel_mm from a taxel's centre, sheared
    while sticking to F_t / F_z = ratio (as compare.fast_side); fresh: its unloaded state."""
    tab = model.tab
    length = model.sim.spacer.width_mm
    delta = float(np.interp(load_n_per_mm, tab.load, tab.delta_mm))
    start = _centre() + taxel_mm
    model.restore_mech_state(fresh)
    rec0 = model.step_many(np.array([0.0]), np.array([[start, 0.0, -delta]]), np.array([np.pi / 2]))[0]
    xs = np.linspace(0.0, 3.0, 601)[1:]
    recs = model.step_many(1e-3 * np.arange(1, len(xs) + 1),
                           np.column_stack([start + xs, np.zeros_like(xs), -delta * np.ones_like(xs)]),
                           np.full(len(xs), np.pi / 2))
    k = int(np.argmax(recs[:, 1] / recs[:, 3] >= ratio))
    rec = recs[k]
    press = reader.counts(np.stack(model.pressure_maps([model.state_of(rec0)]))[:, 0])
    sheared = reader.counts(np.stack(model.pressure_maps([model.state_of(rec)]))[:, 0])
    return signals(press, sheared, float(rec[3]) / length, float(rec[1]) / length, float(rec[6]), start)


def _summary(values: list[float]) -> dict:
    v = np.asarray(values, float)
    return {"mean": float(v.mean()), "min": float(v.min()), "max": float(v.max()), "n": int(v.size)}


def taxel_aligned_means(fem: dict, model) -> dict:
    """{branch depth: {signal: mean over ALIGN_TAXEL_MM}} of one run without walls to align to
    (the homogenised section), as the gate reads it."""
    by: dict = {}
    for t in ALIGN_TAXEL_MM:
        for b, sig in fem_signals(fem, model, t).items():
            by.setdefault(b, []).append(sig)
    return {b: {name: float(np.mean([r[name] for r in rows])) for name in (*SIGNALS, "fz_n_per_mm")}
            for b, rows in sorted(by.items())}


def section_signals(sim, data: Path = DATA, model_hook=None, homogenised: str = "homogenised") -> dict:
    """The section's signals over its alignments: {"cells": {branch: [signals per alignment]},
    "homogenised": {...}} (cells: each wall alignment x each taxel alignment; homogenised: each
    taxel alignment, it has no walls; `homogenised` names its data: "homogenised", inside the
    cells' solid rim, or "homogenised_no_rim"); with the model that read them (model_hook(sim) ->
    sim alters its design, as in compare.compare)."""
    fsim = line_sim(sim, "bonded")
    model = line_model(fsim if model_hook is None else model_hook(fsim))
    runs = {"cells": [load_fem("bonded", data)] + [load_fem(f"alignment/x0_{x0:.2f}", data) for x0 in ALIGN_X0_MM[1:]],
            "homogenised": [load_fem(homogenised, data)]}
    out: dict = {"model": model}
    for kind, fems in runs.items():
        by: dict = {}
        for fem in fems:
            for t in ALIGN_TAXEL_MM:
                for b, sig in fem_signals(fem, model, t).items():
                    by.setdefault(b, []).append(sig)
        out[kind] = by
    return out


def homogenised_for(sim) -> str:
    """The homogenised section that matches the design's rim: "homogenised_no_rim" for a pad whose
    lattice runs out to its sides (sim.spacer.rim_mm=0), else "homogenised" (inside the rim the
    lattice leaves; the reference has no section for another width, and the cells section always
    has that rim)."""
    return "homogenised_no_rim" if sim.spacer.rim_width_mm == 0 else "homogenised"


def alignment_table(sim, data: Path = DATA, model_hook=None) -> dict:
    """{branch: {signal: {"fem": summary, "homogenised": summary, "fast": summary}}} (see the
    module docstring); summaries are mean, min, max over the alignments."""
    sec = section_signals(sim, data, model_hook, homogenised_for(sim))
    model = sec["model"]
    fresh = model.mech_state()  # unloaded, nothing stuck
    fem_by, hom_by = sec["cells"], sec["homogenised"]
    out = {}
    for b, rows in sorted(fem_by.items()):
        load = float(np.mean([r["fz_n_per_mm"] for r in rows]))
        ratio = float(np.mean([r["shear_ratio"] for r in rows]))
        fast = [fast_signals(model, fresh, Reader(model), load, ratio, t) for t in ALIGN_TAXEL_MM]
        out[f"{b:.1f} mm"] = {"fz_n_per_mm": load, "shear_ratio": ratio, **{
            name: {"fem": _summary([r[name] for r in rows]),
                   "homogenised": _summary([r[name] for r in hom_by.get(b, [])]) if hom_by.get(b) else None,
                   "fast": _summary([r[name] for r in fast])} for name in SIGNALS}}
    return out


def gate(sim, data: Path = DATA, tolerances: dict | None = None, model_hook=None,
         bounds=None) -> tuple[list[Comparison], dict]:
    """The fast model against the section as `validate` judges it: compare.compare's rows, with
    every count-CoP shear signal (SIGNALS, and the effective height's rise) judged on its mean
    over the alignments (alignment_table) instead of at the committed section's one alignment,
    where the walls' aliasing decides its sign. The same signals are judged again against the
    section with its lattice homogenised inside the same solid rim (bound "homogenised":
    reference/homogenised.npz, taxel alignments only), the continuum the fast model's lattice is:
    where a count row passes against one section and fails against the other, the walls'
    discreteness decides it, not the stack's continuum mechanics. (The pad's solid rim beyond the
    last full wall carries much of the lattice's side load in both; without it the homogenised
    section's deep count CoP moves 0.758 / 0.946 mm instead of 0.464 / 0.585: homogenisation.json's
    "without_rim".) The bands are the same (tolerances.yaml) for every row. The
    single-alignment values stay in the record (record["bonded"]); the alignment table is
    record["alignments"], and the rows no fast value can pass against both sections
    record["disjoint"] (`disjoint_pairs`)."""
    tol = tolerances or load_tolerances()
    rows, record = compare(sim, data, tol, model_hook=model_hook, bounds=bounds)
    if "bonded" not in (bounds or BOUNDS):
        return rows, record
    averaged = {*SIGNALS, "effective_height_rise"}
    rows = [r for r in rows if not (r.bound == "bonded" and r.metric in averaged)]
    table = {b: row for b, row in alignment_table(sim, data, model_hook).items() if row["shear_ratio"] >= MIN_SHEAR_RATIO}
    record["alignments"] = table

    def add(bound, metric, label, fem_value, fast_value):
        kind, lo, hi = band(tol, metric, fem_value)
        rows.append(Comparison(bound, metric, label, fem_value, fast_value, kind, lo, hi))

    # the cells section, then the same section with its lattice homogenised
    for bound, side in (("bonded", "fem"), ("homogenised", "homogenised")):
        for name in SIGNALS:
            for row in table.values():
                if row[name][side] is not None:
                    add(bound, name, f"{row['fz_n_per_mm']:.3f} N/mm, aligned mean", row[name][side]["mean"],
                        row[name]["fast"]["mean"])
        heights = [table[b]["effective_height_counts"] for b in (min(table), max(table))] if len(table) >= 2 else []
        if heights and all(h[side] is not None for h in heights):
            lo_row, hi_row = heights
            add(bound, "effective_height_rise", "highest / lowest load, aligned means",
                hi_row[side]["mean"] / lo_row[side]["mean"], hi_row["fast"]["mean"] / lo_row["fast"]["mean"])
    record["disjoint"] = disjoint_pairs(rows)
    return rows, record


def accepted_interval(row: Comparison) -> tuple[float, float]:
    """The fast values a row accepts (its band about its FEM value)."""
    if row.kind == "ratio":
        return tuple(sorted((row.lo * row.fem, row.hi * row.fem)))
    return row.fem + row.lo, row.fem + row.hi


def disjoint_pairs(rows: list[Comparison]) -> list[str]:
    """The rows judged against both sections (the cells, "bonded", and the homogenised one) at
    the same metric and load whose accepted intervals do not overlap: no fast value passes both,
    so the two references disagree by more than the tolerances allow there. One line each."""
    by: dict = {}
    for r in rows:
        if r.bound in ("bonded", "homogenised"):
            by.setdefault((r.metric, r.load), {})[r.bound] = r
    out = []
    for (metric, load), pair in by.items():
        if len(pair) < 2:
            continue
        (a_lo, a_hi), (b_lo, b_hi) = accepted_interval(pair["bonded"]), accepted_interval(pair["homogenised"])
        if max(a_lo, b_lo) > min(a_hi, b_hi):
            out.append(f"{metric} at {load}: the cells section accepts [{a_lo:.3g}, {a_hi:.3g}], the homogenised "
                       f"one [{b_lo:.3g}, {b_hi:.3g}]; no fast value passes both")
    return out


def table_text(res: dict) -> str:
    lines = [f"{'branch':8} {'signal':30} {'FEM cells mean [min, max]':>30} {'homogenised':>26} {'fast':>26}"]
    for b, row in res.items():
        for name in SIGNALS:
            cells = [row[name][k] for k in ("fem", "homogenised", "fast")]
            txt = ["-" if c is None else f"{c['mean']:+.3f} [{c['min']:+.2f}, {c['max']:+.2f}]" for c in cells]
            lines.append(f"{b:8} {name:30} {txt[0]:>30} {txt[1]:>26} {txt[2]:>26}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    import argparse

    argparse.ArgumentParser(prog=f"python -m {__spec__.name if __spec__ else __name__}", description=__doc__,
                            formatter_class=argparse.RawDescriptionHelpFormatter).parse_args(argv)
    from layerskin_exp.sim.config import load_sim

    print(f"F_t / F_z = {SHEAR_RATIO:.3f}; FEM: cap at {ALIGN_X0_MM} mm from a wall x {ALIGN_TAXEL_MM} mm "
          f"from a taxel; fast: {ALIGN_TAXEL_MM}")
    print(table_text(alignment_table(load_sim([]))))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
