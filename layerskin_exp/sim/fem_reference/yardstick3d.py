"""The fast hemisphere judged against the 3D half-model of the study's geometry: the gate
`python -m layerskin_exp.sim.validate` exits on.

Both sides are the hemispherical cap on the whole stack (cover, superficial sheet, lattice, deep
sheet). The 3D side is the committed half-model (`shear3d`): its branch pressed to 0.3 mm
(reference/shear3d.npz), and pressed sticking to 0.83 N and to 3 N with a cover that keeps its
volume (shear3d_mid_branch.npz, shear3d_load_branch.npz), and the design at the stiff end of the cover's bracket pressed to 3 N the same way
(shear3d_stiff_cover.npz, `--stiff-cover`), each sheared with the contact sticking, taken at F_t / F_z = 1/3 or at the last ratio the branch
reached; each layer read as its FSR reads it, the pressure along the sheet's normal where it is
now (a tilted, bent sheet's z component also carries its transverse shear force times its slope,
which no FSR reads: shear3d.Stack3D.plane_normals), the superficial one as the mean of the
pressures on the sheet's two faces (what the Velostat between two films that share the sheet's
membrane force feels; the merged sheet's own mid-plane does not carry the load it reads, see
`fem3d_side`). Each gated reading must carry F_z (`superficial_balance`, `deep_balance`). The fast side is the simulator's own skin model (hemisphere mode, noise-free, uniform
gains, the sheet bonded as the 3D model's merged sheet is), pressed at the same spot to the same
F_z and moved along +x while sticking until F_x reaches the same F_t. Every count row goes
through the simulator's FSR law and readout (compare.Reader) and is averaged over 4 x 4 taxel
alignments (alignment.ALIGN_TAXEL_MM along x and across) on both sides. The bands are fixed in
tolerances.yaml (`yardstick3d:`).

Rows per state: the cap's depth at that F_z, the contact's radius, the peak superficial pressure
and the peak deep taxel pressure at the press; the tangential stiffness (F_t over the cap's
travel, secant from the press), the sheet's travel over the deep sheet under the cap, the
superficial and the deep count-CoP travel from the press (each layer in its own taxel frame) and
the change of the inter-layer count shift. Reported beside them, not gated: the deep force CoP's
travel against its own statics, x_cap + F_x H / F_z - x_cap,0 on each side, and the effective
height F_z dc / F_t; the superficial pressure's asymmetry about the sheet's point under the cap
(its 3D value changes by 116 % with a second element through the cover: tolerances.yaml); the
superficial count-CoP travel and the inter-layer shift read from the
merged sheet's mid-plane along its normal, with how far that reading misses F_z; each reading's
load balance.

`python -m layerskin_exp.sim.fem_reference.yardstick3d` prints the table.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from layerskin_exp.sim import mechanics as mk
from layerskin_exp.sim.config import SimConfig
from layerskin_exp.sim.fem_reference.alignment import ALIGN_TAXEL_MM, _centre
from layerskin_exp.sim.fem_reference.compare import (
    DATA,
    SHEAR_RATIO,
    SKIN,
    Comparison,
    Reader,
    _asymmetry,
    _cop_x,
    line_sim,
    load_fem,
    load_tolerances,
)
from layerskin_exp.sim.skin import SkinModel

# the 3D states compared: (label, data file, which branch: its press depth, or None for the
# file's one sheared branch), per design: the nominal one, and the stiff end of the cover's bracket
# (shear3d.STIFF_COVER_KPA, `--stiff-cover`)
STATES = (("0.22 N", "shear3d", 0.3), ("0.83 N", "shear3d_mid_branch", None), ("3 N", "shear3d_load_branch", None))
STIFF_STATES = (("stiff cover 3 N", "shear3d_stiff_cover", None),)
GATED_DIFFERENCE = ("deep_cop_counts_mm", "superficial_cop_counts_mm", "interlayer_shift_counts_mm", "sheet_travel_mm")
GATED_RATIO = ("depth_at_load", "contact_radius", "peak_superficial_kpa", "peak_deep_taxel_kpa", "tangential_stiffness")
REPORTED = ("deep_force_cop_mm", "deep_force_cop_statics_mm", "effective_height_counts", "superficial_asymmetry_counts",
            "shear_ratio", "fz_n",
            "superficial_cop_counts_mid_plane_mm", "interlayer_shift_counts_mid_plane_mm", "superficial_balance",
            "superficial_mid_plane_balance", "deep_balance")


def _state(res: dict, depth: float | None) -> dict:
    """The branch's press state and its sheared state at F_t / F_z = SHEAR_RATIO (linear between
    the states around it), or its last state where it stopped short."""
    sheared = res["phase"] == 1
    if depth is None:
        branch = float(np.unique(res["branch_depth_mm"][sheared])[0])
    else:
        branch = float(depth)
    idx = np.flatnonzero(sheared & np.isclose(res["branch_depth_mm"], branch))
    start = int(np.flatnonzero((res["phase"] == 0) & np.isclose(res["depth_mm"], branch))[0]) if depth is not None \
        else int(np.flatnonzero(res["phase"] == 0)[0])
    ratio = res["fx_n"][idx] / res["fz_n"][idx]
    if ratio.max() >= SHEAR_RATIO:
        k = int(np.argmax(ratio >= SHEAR_RATIO))
        r0 = 0.0 if k == 0 else ratio[k - 1]
        t = (SHEAR_RATIO - r0) / (ratio[k] - r0)
    else:
        k, t = len(idx) - 1, 1.0
    i1, i0 = idx[k], (idx[k - 1] if k > 0 else start)
    maps = tuple(f"{plane}{reading}" for plane in ("superficial", "deep", "sheet_top", "sheet_bottom")
                 for reading in ("_kpa", "_normal_kpa"))
    out = {key: (1 - t) * np.asarray(res[key][i0], float) + t * np.asarray(res[key][i1], float)
           for key in ("cap_x_mm", "fx_n", "fz_n", "sheet_shift_mm", "sheet_x_under_cap_mm", *maps) if key in res}
    out["start"] = start
    return out


def _force_cop(xy: np.ndarray, p: np.ndarray, w: np.ndarray) -> float:
    f = np.asarray(p, float) * np.asarray(w, float)  # signed: statics holds for the whole load
    return float((xy[:, 0] * f).sum() / f.sum())  # the half-model is symmetric in y


def _alignments():
    return [(tx, ty) for tx in ALIGN_TAXEL_MM for ty in ALIGN_TAXEL_MM]


def _count_rows(press: np.ndarray, sheared: np.ndarray, start_mm: float, under_mm: float) -> dict:
    """Count signals of one sheared state from its press, counts (2, 16, 16) in the taxel grid's
    frame: start_mm, where the cap pressed; under_mm, the superficial sheet's point under the cap
    now (where the superficial taxels see the contact)."""
    return {"superficial_cop_counts_mm": _cop_x(sheared[0]) - _cop_x(press[0]),
            "deep_cop_counts_mm": _cop_x(sheared[1]) - _cop_x(press[1]),
            "interlayer_shift_counts_mm": (_cop_x(sheared[0]) - _cop_x(sheared[1])) - (_cop_x(press[0]) - _cop_x(press[1])),
            "superficial_asymmetry_counts": _asymmetry(sheared[0], under_mm) - _asymmetry(press[0], start_mm)}


def _mean_counts(rows: list[dict]) -> dict:
    return {k: float(np.mean([r[k] for r in rows])) for k in rows[0]}


def fem3d_side(label: str, name: str, depth: float | None, model: SkinModel, data: Path = DATA) -> dict:
    """The 3D model's values at one state (see the module's docstring)."""
    res = load_fem(name, data)
    s = _state(res, depth)
    st = s["start"]
    # each layer as its FSR reads it: the pressure along the sheet's normal where it is now
    # (shear3d.Stack3D.plane_normals); data solved before that was recorded have the z component
    reading = "_normal_kpa" if "superficial_normal_kpa" in res else "_kpa"
    sup, deep = f"superficial{reading}", f"deep{reading}"
    # The superficial sheet is read from its two faces where the data have them
    # (shear3d.Stack3D.line_z): the mean of the cover's and the lattice's pressure on it, what a
    # soft core between films sharing the sheet's membrane force feels, and a reading that carries
    # the load (within 1 %). The merged sheet's mid-plane does not (its nodal forces carry the
    # sheet's membrane and bending forces, which a tilted normal picks up: 1.5 to 3 times F_z);
    # it is reported beside, and gated only for data solved before the faces were read.
    has_faces = f"sheet_top{reading}" in res
    if has_faces:
        geometry = {**res, "superficial_xy_mm": res["sheet_top_xy_mm"], "superficial_w_mm2": res["sheet_top_w_mm2"]}
        top, bottom = f"sheet_top{reading}", f"sheet_bottom{reading}"
        sup_press = 0.5 * (np.asarray(res[top], float) + np.asarray(res[bottom], float))[st]
        sup_now = 0.5 * (np.asarray(s[top], float) + np.asarray(s[bottom], float))
    else:
        geometry, sup_press, sup_now = res, np.asarray(res[sup], float)[st], np.asarray(s[sup], float)
    counts, mid_plane, peak_deep = [], [], []
    for tx, ty in _alignments():
        reader = Reader(model, shift_mm=-tx - _centre(), shift_y_mm=-ty - _centre())
        # the cap's point on the superficial sheet at the press and now, in the taxel grid's frame
        where = (float(res["cap_x_mm"][st]) - reader.shift_mm, float(s["sheet_x_under_cap_mm"]) - reader.shift_mm)
        press_maps = reader.maps(geometry, sup_press, res[deep][st])
        peak_deep.append(float(press_maps[1].max()))
        counts.append(_count_rows(reader.counts(press_maps), reader.counts(reader.maps(geometry, sup_now, s[deep])), *where))
        if has_faces:
            mid_plane.append(_count_rows(reader.counts(reader.maps(res, res[sup][st], res[deep][st])),
                                         reader.counts(reader.maps(res, s[sup], s[deep])), *where))
    fz, fx = float(res["fz_n"][st]), float(s["fx_n"])
    travel = float(s["cap_x_mm"] - res["cap_x_mm"][st])

    def balance(start, now, w):  # worst |2 sum(p A) / F_z - 1| of a reading at the press and sheared
        return max(abs(2e-3 * float(np.asarray(p, float) @ w) / f - 1.0) for p, f in ((start, fz), (now, float(s["fz_n"]))))

    # (statics: the z component, the load's own)
    deep_cop = _force_cop(res["deep_xy_mm"], s["deep_kpa"], res["deep_w_mm2"]) - \
        _force_cop(res["deep_xy_mm"], res["deep_kpa"][st], res["deep_w_mm2"])
    sim = model.sim  # the 3D model is built from the same design's layers
    height = sim.cover.thickness_mm + sim.fsr.layer_thickness_mm + sim.spacer.thickness_mm - float(res["depth_mm"][st])
    out = {"label": label, "fz_n": fz, "ft_n": fx, "shear_ratio": fx / float(s["fz_n"]),
           "depth_at_load": float(res["depth_mm"][st]),
           "contact_radius": float(res["contact_to_mm"][st]),
           "peak_superficial_kpa": float(sup_press.max()),
           "peak_deep_taxel_kpa": float(np.mean(peak_deep)),
           "tangential_stiffness": fx / travel,
           "sheet_travel_mm": float(s["sheet_shift_mm"] - res["sheet_shift_mm"][st]),
           "deep_force_cop_mm": deep_cop,
           "deep_force_cop_statics_mm": travel + fx * height / float(s["fz_n"]),
           **_mean_counts(counts)}
    # a reading is a yardstick only if it carries the load it reads (the half-model's: twice its sum)
    out["superficial_balance"] = balance(sup_press, sup_now, geometry["superficial_w_mm2"])
    out["deep_balance"] = balance(res[deep][st], s[deep], res["deep_w_mm2"])
    if has_faces:
        out["superficial_mid_plane_balance"] = balance(res[sup][st], s[sup], res["superficial_w_mm2"])
    dc = out["interlayer_shift_counts_mm"]
    out["effective_height_counts"] = -fz * dc / fx if fx > 0 else float("nan")
    if mid_plane:
        mean_mid = _mean_counts(mid_plane)
        out["superficial_cop_counts_mid_plane_mm"] = mean_mid["superficial_cop_counts_mm"]
        out["interlayer_shift_counts_mid_plane_mm"] = mean_mid["interlayer_shift_counts_mm"]
    return out


def fast_sim(sim: SimConfig) -> SimConfig:
    """The design as the 3D model is read: noise-free, uniform gains, the sheet bonded."""
    return line_sim(sim, "bonded")


def fast_model(sim: SimConfig) -> SkinModel:
    return SkinModel(fast_sim(sim), SKIN, "hemisphere", np.random.default_rng(0))


def fast_side(model: SkinModel, fresh: np.ndarray, fz_n: float, ft_n: float, travel_mm: float = 4.0,
              steps: int = 800) -> dict:
    """The fast hemisphere pressed to fz_n at each taxel alignment and moved along +x while
    sticking until F_x reaches ft_n (ValueError where it slides or runs out of travel first);
    fresh: the model's unloaded state (`SkinModel.mech_state` before any contact)."""
    tab = model.tab
    delta = float(np.interp(fz_n, tab.load, tab.delta_mm))
    reader = Reader(model)
    counts, peak_deep, rows = [], [], None
    for tx, ty in _alignments():
        x0, y0 = _centre() + tx, _centre() + ty
        model.restore_mech_state(fresh)
        rec0 = model.step_many(np.array([0.0]), np.array([[x0, y0, -delta]]), np.zeros(1))[0]
        xs = np.linspace(0.0, travel_mm, steps + 1)[1:]
        recs = model.step_many(1e-3 * np.arange(1, steps + 1),
                               np.column_stack([x0 + xs, np.full(steps, y0), np.full(steps, -delta)]), np.zeros(steps))
        reached = np.flatnonzero(recs[:, 1] >= ft_n)
        if len(reached) == 0 or recs[: reached[0] + 1, 12].any():
            raise ValueError(f"the fast model did not reach F_x {ft_n:.3f} N sticking at F_z {fz_n:.3f} N "
                             f"within {travel_mm} mm (largest {recs[:, 1].max():.3f} N)")
        k = int(reached[0])
        # linear between the step before and the one that reached ft_n
        f0 = recs[k - 1, 1] if k else rec0[1]
        t = (ft_n - f0) / max(recs[k, 1] - f0, 1e-12)
        rec = (1 - t) * (recs[k - 1] if k else rec0) + t * recs[k]
        maps0 = np.stack(model.pressure_maps([model.state_of(rec0)]))[:, 0]
        maps1 = np.stack(model.pressure_maps([model.state_of(rec)]))[:, 0]
        peak_deep.append(float(maps0[1].max()))
        # the cap's point on the superficial sheet (its frame is the superficial taxels') at the
        # press and now
        counts.append(_count_rows(reader.counts(maps0), reader.counts(maps1), float(rec0[mk.S_CX]), float(rec[mk.S_CX])))
        if rows is None:  # the mechanics do not depend on the alignment
            travel = float((1 - t) * (xs[k - 1] if k else 0.0) + t * xs[k])
            rows = {"depth_at_load": delta,
                    "contact_radius": float(np.interp(delta, tab.delta_mm, tab.contact_halfwidth_mm)),
                    "peak_superficial_kpa": float(np.interp(delta, tab.delta_mm, tab.cover_kpa.max(axis=1))),
                    "tangential_stiffness": ft_n / travel,
                    "sheet_travel_mm": float(rec[9] - rec0[9]),
                    "deep_force_cop_mm": _deep_force_cop(model, rec) - _deep_force_cop(model, rec0),
                    "deep_force_cop_statics_mm": travel + ft_n * float(np.interp(delta, tab.delta_mm, tab.height_mm))
                    / float(rec[3])}
    out = {**rows, "peak_deep_taxel_kpa": float(np.mean(peak_deep)), **_mean_counts(counts)}
    out["effective_height_counts"] = -fz_n * out["interlayer_shift_counts_mm"] / ft_n
    return out


def _deep_force_cop(model: SkinModel, rec: np.ndarray, step_mm: float = 0.05) -> float:
    """x of the force CoP of the fast model's signed pressure on the deep plane, over the whole
    pad and the reach of what its sides carry (the numpy reference's fields,
    `reference.ReferenceSkin.signed_fields`; the lattice's route at the sides is blurred across
    them, so a grid cut at the sides loses part of its moment)."""
    from layerskin_exp.sim.reference import ReferenceSkin

    tab = model.tab
    half = max(float(np.abs(tab.edge_dist_mm).max()), 0.5 * model.sim.spacer.width_mm) + 2.0
    g = np.arange(-half, half + 1e-9, step_mm)
    x, y = np.meshgrid(g, g)
    _, base, _ = ReferenceSkin(model).signed_fields(rec, x, y)
    return float((base * x).sum() / base.sum())


def rows(sim: SimConfig, data: Path = DATA, tolerances: dict | None = None, model_hook=None) -> tuple[list[Comparison], dict]:
    """The gated comparisons (compare.Comparison, bound "3d") of every state, and the record:
    {state label: {"3d": values, "fast": values}} with the reported rows. model_hook(sim) -> sim
    alters the fast model's design (the tests inject errors through it)."""
    from layerskin_exp.sim.fem_reference.shear3d import stiff_cover_sim

    tol = (tolerances or load_tolerances())["yardstick3d"]
    out, record = [], {}
    for design, states in ((sim, STATES), (stiff_cover_sim(sim), STIFF_STATES)):
        _design_rows(design if model_hook is None else model_hook(design), states, data, tol, out, record)
    return out, record


def _design_rows(fsim: SimConfig, states, data: Path, tol: dict, out: list, record: dict) -> None:
    model = fast_model(fsim)
    fresh = model.mech_state()  # unloaded, nothing stuck
    for label, name, depth in states:
        if not (data / f"{name}.npz").exists():  # a design without its 3D data is not judged: it fails
            record[label] = {"3d": None, "fast": None, "error": f"no 3D data {name}.npz (python -m "
                             "layerskin_exp.sim.fem_reference --stiff-cover)"}
            out.extend(_comparison(tol, m, label, float("nan"), float("nan")) for m in (*GATED_DIFFERENCE, *GATED_RATIO))
            continue
        fem = fem3d_side(label, name, depth, model, data)
        try:
            fast = fast_side(model, fresh, fem["fz_n"], fem["ft_n"])
        except ValueError as exc:
            record[label] = {"3d": fem, "fast": None, "error": str(exc)}
            for metric in (*GATED_DIFFERENCE, *GATED_RATIO):
                out.append(_comparison(tol, metric, label, fem[metric], float("nan")))
            continue
        record[label] = {"3d": fem, "fast": fast}
        for metric in (*GATED_DIFFERENCE, *GATED_RATIO):
            out.append(_comparison(tol, metric, label, fem[metric], fast[metric]))


def _comparison(tol: dict, metric: str, label: str, fem: float, fast: float) -> Comparison:
    if metric in tol["difference"]:
        lim = float(tol["difference"][metric])
        return Comparison("3d", metric, label, fem, fast, "difference", -lim, lim)
    lo, hi = tol["ratio"][metric]
    return Comparison("3d", metric, label, fem, fast, "ratio", float(lo), float(hi))


def table_text(comparisons: list[Comparison], record: dict) -> str:
    lines = [f"{'state':15} {'metric':28} {'3D':>10} {'fast':>10} {'judged':>9} {'band':>16}  ok"]
    for c in comparisons:
        lines.append(f"{c.load:15} {c.metric:28} {c.fem:10.4g} {c.fast:10.4g} {c.value:9.3g} "
                     f"{f'[{c.lo:.3g}, {c.hi:.3g}]':>16}  {'yes' if c.passed else 'NO'}")
    for label, rec in record.items():
        if rec.get("fast") is None:
            lines.append(f"{label}: {rec['error']}")
            continue
        for metric in REPORTED:
            f3, ff = rec["3d"].get(metric), rec["fast"].get(metric)
            if metric.endswith("_mid_plane_mm"):  # the 3D sheet's mid-plane beside the fast superficial reading
                ff = rec["fast"].get(metric.replace("_mid_plane_mm", "_mm"))
            if f3 is None:
                continue  # 3D data solved before the states recorded it
            lines.append(f"{label:15} {metric:28} {f3:10.4g} {'' if ff is None else format(ff, '10.4g'):>10}   (reported)")
    return "\n".join(lines)


# Designs printed beside the default in the record (`--json`): what each ingredient of the sheet's
# mechanics does to the rows; they gate nothing.
VARIANTS = {"smooth sheet (sim.sheet.wrinkling=false)": ["sim.sheet.wrinkling=false"],
            "bending plate (sim.sheet.large_deflection=false)": ["sim.sheet.large_deflection=false"]}


def record_json(overrides: list[str] | None = None, variants: bool = True) -> dict:
    """The rows of the design `overrides` names (and, with `variants`, those of VARIANTS) as JSON:
    {"designs": {name: {"overrides", "rows": [{state, metric, 3d, fast, value, lo, hi, kind,
    passed}], "passed", "total"}}}."""
    from layerskin_exp.sim.config import load_sim

    designs = {"default": list(overrides or [])}
    if variants:
        designs.update({name: [*designs["default"], *extra] for name, extra in VARIANTS.items()})
    out = {}
    for name, ov in designs.items():
        comparisons, _ = rows(load_sim(ov))
        out[name] = {"overrides": ov, "passed": sum(c.passed for c in comparisons), "total": len(comparisons),
                     "rows": [{"state": c.load, "metric": c.metric, "3d": c.fem, "fast": c.fast, "value": c.value,
                               "lo": c.lo, "hi": c.hi, "kind": c.kind, "passed": bool(c.passed)}
                              for c in comparisons]}
    return {"designs": out}


def main(argv: list[str] | None = None) -> int:
    import argparse
    import json

    ap = argparse.ArgumentParser(prog=f"python -m {__spec__.name if __spec__ else __name__}", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--json", metavar="OUT", help="also write the rows of the design and of the variants beside it "
                    "(the smooth sheet, the bending plate) to OUT as JSON, for docs/simulator-validation.md")
    args = ap.parse_args(argv)
    from layerskin_exp.sim.config import load_sim

    comparisons, record = rows(load_sim([]))  # another design: python -m layerskin_exp.sim.validate sim.KEY=VALUE
    print(table_text(comparisons, record))
    if args.json:
        from pathlib import Path

        Path(args.json).write_text(json.dumps(record_json(), indent=1) + "\n")
    return 0 if all(c.passed for c in comparisons) else 1


if __name__ == "__main__":
    raise SystemExit(main())
