"""report.md: each table of the study with our value beside the study's ("ours (study)")."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def json_safe(x):
    """Results as plain Python for JSON and the tables: numpy scalars/arrays to Python, NaN/inf to None."""
    if isinstance(x, dict):
        return {str(k): json_safe(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [json_safe(v) for v in x]
    if isinstance(x, np.ndarray):
        return json_safe(x.tolist())
    if isinstance(x, (np.floating, float)):
        return float(x) if np.isfinite(x) else None
    if isinstance(x, np.integer):
        return int(x)
    return x


def counted(n: int, noun: str) -> str:
    """'1 trial', '4 trials': a count with its noun, in the report's sentences."""
    return f"{n} {noun}{'' if n == 1 else 's'}"


def _f(x, nd=3) -> str:
    return "–" if x is None else f"{x:.{nd}f}"


def _pair(ours, theirs, nd=3) -> str:
    return f"{_f(ours, nd)} ({_f(theirs, nd)})"


def _get(d, *keys):
    for k in keys:
        if not isinstance(d, dict) or k not in d:
            return None
        d = d[k]
    return d


def _produced_by(r) -> list[str]:
    """What made this report and on how much data; models not to compare with the study yet."""
    p, d = r.get("provenance") or {}, r.get("data") or {}
    commit = p.get("git_commit")
    commit = "none (not a git checkout)" if commit is None else f"`{commit[:12]}`" + (
        " (**dirty**: uncommitted changes)" if p.get("git_dirty") else " (clean)")
    lines = ["## Produced by", "",
             f"- analysis preset: **{p.get('analysis_preset') or 'custom (library call)'}**; resolved config in "
             f"`{p.get('config_file', 'config.yaml')}`",
             f"- {p.get('package', 'layerskin-exp')} {p.get('version')}, git commit {commit}, Python {p.get('python')}"]
    if p.get("overrides"):
        lines.append("- overrides: " + " ".join(f"`{o}`" for o in p["overrides"]))
    if d:
        lines.append(f"- data: {d.get('sessions_used')} sessions used, {d.get('sessions_skipped')} skipped; "
                     f"{d.get('calibration_trials')} calibration trials ({d.get('calibration_frames')} frames), "
                     f"{d.get('grip_trials')} grip trials ({d.get('grip_frames')} frames)")
    sp = d.get("split")
    if sp:
        lines.append("- force split (train/val/test): " + " / ".join(
            f"{sp[k]['trials']} trials, {sp[k]['frames']} frames" for k in ("train", "val", "test")))
    fr = d.get("force_range_n")
    if fr:
        lines.append("- force range in the data: " + _ranges(fr) + " (study: " + _study_ranges(r["study"]) + ")")
    training = r.get("force_training") or {}
    for name, t in training.items():
        state = "early stopping triggered" if t.get("early_stopped") else "early stopping not triggered"
        flag = "" if t.get("converged", True) else " — **not converged**: " + "; ".join(t.get("caveats", []))
        lines.append(f"- {name}: {t.get('epochs')}/{t.get('max_epochs')} epochs, best at epoch "
                     f"{t.get('best_epoch')}, {state}{flag}")
    if any(not t.get("converged", True) for t in training.values()):
        lines += ["", "> **Caveat:** the models marked not converged had not finished learning; their rows are "
                  "not a comparison with the study's (train longer, e.g. `analysis=default` or `analysis=paper`)."]
    return lines + [""]


def _ranges(fr) -> str:
    out = [f"{ax} {_f(fr[ax]['min_n'], 2)} to {_f(fr[ax]['max_n'], 2)} N" for ax in ("Fx", "Fy", "Fz") if ax in fr]
    if "test_shear_p5_p95_n" in fr:
        lo, hi = fr["test_shear_p5_p95_n"]
        out.append(f"test shear |Fxy| 5–95 % {_f(lo, 2)}–{_f(hi, 2)} N")
    return ", ".join(out)


def _study_ranges(s) -> str:
    fr = s.get("force_range_n", {})
    return (f"Fx, Fy within about ±{fr['Fx']['max_n']:g} N, |Fz| up to about {fr['abs_Fz_max_n']:g} N"
            if fr else "not stated")


def _gain_cell(g) -> str:
    """'+0.484 [+0.279, +0.757]'; '+0.484 [interval undefined]' with too few test trials for one."""
    def one(x):
        return "–" if x is None or x != x else f"{x:+.3f}"
    if not g:
        return "–"
    gain, lo, hi = g
    if lo is None or lo != lo or hi is None or hi != hi:
        return f"{one(gain)} [interval undefined]"
    return f"{one(gain)} [{one(lo)}, {one(hi)}]"


def _force(r, s) -> list[str]:
    models = list(r["force"])
    if not models:
        return []
    training = r.get("force_training") or {}
    header = [m + (" ⚠" if not training.get(m, {}).get("converged", True) else "") for m in models]
    lines = ["## Force estimation (test trials)", "", "R² and MAE (N) per axis; ours (study). "
             "⚠: model not converged (see Produced by).", "",
             "| axis | metric | " + " | ".join(header) + " |", "|---|---|" + "---|" * len(models)]
    for ax in ("Fx", "Fy", "Fz"):
        for met, label in (("r2", "R²"), ("mae", "MAE (N)")):
            cells = [_pair(_get(r["force"], m, ax, met), _get(s["force"], m, ax, met)) for m in models]
            lines.append(f"| {ax} | {label} | " + " | ".join(cells) + " |")
    gains = r.get("force_gain_over_linear") or {}
    cnns = [m for m in models if m in gains and m != "confidence"]
    if cnns:
        pct = round(100 * gains["confidence"])
        n_test, n_min = r.get("force_split", {}).get("test_trials"), gains.get("min_test_trials")
        lines += ["", f"Gain over the linear baseline, R² difference with its {pct} % interval (bootstrap over "
                  f"the {n_test} test trials; an interval holding 0 is not resolved by this test set"
                  + (f"; below {n_min} test trials the interval is undefined" if n_min else "") + "):", "", "| axis | " + " | ".join(f"{m} − linear" for m in cnns) + " |",
                  "|---|" + "---|" * len(cnns)]
        for ax in ("Fx", "Fy", "Fz"):
            lines.append(f"| {ax} | " + " | ".join(_gain_cell(gains[m].get(ax)) for m in cnns) + " |")
    sp = r.get("force_split", {})
    lines += ["", f"Split by trial: {sp.get('train_trials')}/{sp.get('val_trials')}/{sp.get('test_trials')} "
              f"train/val/test trials, {sp.get('test_frames')} test frames (seed {sp.get('seed')}).", ""]
    fr = (r.get("data") or {}).get("force_range_n")
    if fr:
        lines += ["Reference force ranges — a narrower range is easier data, so higher R² here is not by itself "
                  "a better model:", "", "| axis | ours (N) | study (N) |", "|---|---|---|"]
        st = s.get("force_range_n", {})
        for ax in ("Fx", "Fy"):
            theirs = f"{st[ax]['min_n']:g} to {st[ax]['max_n']:g}" if ax in st else "–"
            lines.append(f"| {ax} | {_f(fr[ax]['min_n'], 2)} to {_f(fr[ax]['max_n'], 2)} | {theirs} |")
        abs_fz = max(abs(fr["Fz"]["min_n"]), abs(fr["Fz"]["max_n"]))
        lines.append(f"| \\|Fz\\| max | {_f(abs_fz, 2)} | {st.get('abs_Fz_max_n', '–')} |")
        if "test_shear_p5_p95_n" in fr:
            lo, hi = fr["test_shear_p5_p95_n"]
            lines.append(f"| test shear \\|Fxy\\| 5–95 % | {_f(lo, 2)}–{_f(hi, 2)} | – |")
        lines.append("")
    return lines


def _characterization(r, s) -> list[str]:
    c, sc = r.get("characterization") or {}, s["characterization"]
    h, sh = r.get("heights") or {}, s["heights"]
    if not c and not h:
        return []
    lines = ["## Characterisation", ""]
    if set(c) - {"sensitivity_bands"} or h:
        lines += ["| quantity | ours | study |", "|---|---|---|"]
    u = c.get("uniformity") or {}
    if u:
        lines.append(f"| CV across positions at {u.get('matched_load_n')} N | {_f(u.get('cv'))} "
                     f"[{_f(u.get('ci_low'))}–{_f(u.get('ci_high'))}], {u.get('n_positions')} positions | "
                     f"{sc['uniformity']['cv']} [{sc['uniformity']['ci_low']}–{sc['uniformity']['ci_high']}], 100 |")
    rp = c.get("repeatability") or {}
    if rp:
        lines.append(f"| median within-position CV | {_f(rp.get('median_cv'))}, {rp.get('n_positions')} positions | "
                     f"{sc['repeatability']['median_cv']}, 88 |")
    cs = c.get("cop_shift") or {}
    if cs:
        lines.append(f"| CoP shift at 1.9–2.1 N shear (mm) | {_f(cs.get('median_mm'), 2)} "
                     f"[{_f(cs.get('p10_mm'), 2)}–{_f(cs.get('p90_mm'), 2)}], {cs.get('n_trials')} trials | "
                     f"{sc['cop_shift']['median_mm']} [{sc['cop_shift']['p10_mm']}–{sc['cop_shift']['p90_mm']}] |")
    sl = c.get("slide_loads") or {}
    if sl:
        lines.append(f"| normal load while \\|F_xy\\| >= {sl.get('shear_at_n', 1.5):g} N, median (N); largest shear "
                     f"per slide, median (N) | {_f(sl.get('fz_at_shear_n'), 2)}; {_f(sl.get('median_max_shear_n'), 2)}, "
                     f"{sl.get('n_trials')} slides | about 6 (\"±2 N shear force at approximately 6 N normal load\"); "
                     "2 N target |")
    if h:
        o = h.get("overall", {})
        lines.append(f"| h_x / h_y overall (mm) | {_f(o.get('h_x_mm'), 2)} / {_f(o.get('h_y_mm'), 2)} "
                     f"(R² {_f(o.get('r2_x'))} / {_f(o.get('r2_y'))}) | {sh['overall']['h_x_mm']} / {sh['overall']['h_y_mm']} |")
        lines += ["", "Effective heights per normal-load bin (study: 0.5–1.0 N: h 1.62/1.44 mm, R² 0.159/0.125; "
                  "5.0–6.5 N: h 4.84/6.53 mm, R² 0.626/0.725):", "",
                  "| F_z bin (N) | frames | h_x (mm) | h_y (mm) | R² x | R² y |", "|---|---|---|---|---|---|"]
        for b in h.get("bins", []):
            lines.append(f"| {b['fz_low_n']}–{b['fz_high_n']} | {b['n_frames']} | {_f(b.get('h_x_mm'), 2)} | "
                         f"{_f(b.get('h_y_mm'), 2)} | {_f(b.get('r2_x'))} | {_f(b.get('r2_y'))} |")
    return lines + [""] + _sensitivity_bands(c.get("sensitivity_bands"))


def _g(x) -> str:
    return "–" if x is None else f"{x:.3g}"


def _sensitivity_bands(sb) -> list[str]:
    """The simulator's band per headline outcome beside the study and this campaign; without a
    screening result, how to make one."""
    from analysis.sensitivity_result import HOW_TO

    if not sb:
        return [f"Sensitivity bands: none given. {HOW_TO}.", ""]
    lines = ["### Simulator sensitivity bands", "",
             f"From `{sb['file']}`: {sb['n_samples']} Morris samples over {len(sb['parameters'])} parameters, each a "
             f"short calibration campaign ({' '.join(f'`{o}`' for o in sb.get('campaign') or [])}). "
             f"The band is the simulator's uncertainty over the brackets of `{sb.get('brackets_file')}` "
             "(min..max of the outcome over the samples, all run with one seed), not measurement noise. "
             "mu*: the outcome's mean change per full bracket.", "",
             "| outcome | study | this campaign | band over the brackets | moved most by (mu*) |", "|---|---|---|---|---|"]
    said = []
    for r in sb["rows"]:
        unit = f" ({r['unit']})" if r["unit"] else ""
        approx = "≈ " if r.get("study_approximate") else ""
        study = (f"{approx}{_g(r['study'])} ({r['study_source']})" if r["study"] is not None
                 else f"– ({r['study_source']})")
        ours = f"{_g(r['ours'])} ({r['ours_source']})" if r["ours"] is not None else "–"
        if r["band"] is None:
            band = f"– ({r.get('reason', 'undefined')})"
        else:
            band = f"{_g(r['band'][0])} .. {_g(r['band'][1])}"
            if r["missing"]:
                band += f" ({r['missing']} of {sb['n_samples']} samples undefined)"
        moved = ", ".join(f"`{m['parameter']}` ({_g(m['mu_star'])})" for m in r["moved_most_by"]) or (
            "none (constant over the samples)" if r["band"] is not None else "–")
        lines.append(f"| {r['label']}{unit} | {study} | {ours} | {band} | {moved} |")
        where = r["study_vs_band"]
        value_unit = f" {r['unit']}" if r["unit"] not in ("", "fraction") else ""
        if where in ("above", "below"):
            said.append(f"- {r['label']}: the study's {approx}{_g(r['study'])}{value_unit} lies {where} the band "
                        f"({_g(r['band'][0])} .. {_g(r['band'][1])}{value_unit}): none of the {sb['n_samples']} screened "
                        "settings of the simulator reached it.")
        elif where == "inside":
            said.append(f"- {r['label']}: the study's {approx}{_g(r['study'])}{value_unit} lies inside the band.")
    if said:
        lines += ["", "Where the study's value lies against the band (a result to read, not a pass/fail):", ""] + said
    return lines + [""]


def _tracking(r, s) -> list[str]:
    t = r.get("tracking") or {}
    if not t:
        return []
    lines = ["## Contact-motion tracking (LOTO per grip depth)", "",
             "Slope a (mean over folds), pooled out-of-fold R², MAE (mm or °); ours (study).", "",
             "| motion | g (mm) | deep a | deep R² | deep MAE | sup. a | sup. R² | sup. MAE |", "|---|---|---|---|---|---|---|---|"]
    for motion, layers in t.items():
        depths = sorted({g for lay in layers.values() for g in lay}, key=float)
        for g in depths:
            cells = []
            for layer in ("deep", "superficial"):
                for k, nd in (("a", 2), ("r2", 3), ("mae", 2)):
                    cells.append(_pair(_get(layers, layer, g, k), _get(s["tracking"], motion, layer, g, k), nd))
            lines.append(f"| {motion} | {g} | " + " | ".join(cells) + " |")
    pre = r.get("preload_n")
    if pre:
        lines += ["", "Mean normal preload from the T-s5 model (N): " + ", ".join(
            f"g={g} mm: {_f(v, 2)} ({s['preload_n'].get(g, '–')})" for g, v in pre.items())]
    return lines + [""]


def _slip(r, s) -> list[str]:
    sl = r.get("slip") or {}
    if not sl:
        return []
    lines = ["## Slip-event detection (trial-macro F1, LOTO)", "", "ours (study).", "",
             "| motion | cue | Global | Grip | Oracle | events | median offset (ms) |", "|---|---|---|---|---|---|---|"]
    for motion, cues in sl.items():
        for cue, v in cues.items():
            cells = [_pair(v.get(k), _get(s["slip"], motion, cue, k)) for k in ("global", "grip", "oracle")]
            lines.append(f"| {motion} | {cue} | " + " | ".join(cells) +
                         f" | {v.get('n_truth_events')} | {_f(1e3 * v['median_offset_s'], 0)} |")
    return lines + [""]


def _slip_causal(r) -> list[str]:
    sc, off = r.get("slip_causal") or {}, r.get("slip") or {}
    if not sc:
        return []
    lines = ["## Slip detection live: causal vs offline (trial-macro F1, LOTO)", "",
             "Causal: causal band-pass, backward difference, trailing RMS envelope, normalisation frozen at "
             "fit (what OnlineEstimator runs). Offline: the study's zero-phase pipeline. Same trials, truth, "
             "threshold grid and LOTO settings.", "",
             "| motion | cue | Global causal (offline) | Grip causal (offline) | Oracle causal (offline) |",
             "|---|---|---|---|---|"]
    for motion, cues in sc.items():
        for cue, v in cues.items():
            cells = [_pair(v.get(k), _get(off, motion, cue, k)) for k in ("global", "grip", "oracle")]
            lines.append(f"| {motion} | {cue} | " + " | ".join(cells) + " |")
    return lines + [""]


HEALTH_COUNTERS = ("received", "lost", "dropped", "duplicate", "out_of_order", "corrupt", "reconnects")


def _stream_health(r) -> list[str]:
    """The drivers' stream-health counters summed over the sessions used, one row per device."""
    h = r.get("stream_health")
    if not h or not h.get("sessions"):
        return []
    lines = ["## Stream health", "",
             f"The drivers' counters summed over {counted(h['sessions'], 'session')} used (lost: sequence gaps; "
             f"dropped: frames a full driver buffer let go); {h['sessions_with_lost_skin_frames']} with lost skin "
             "frames (within their run's max_lost_skin_frames)"
             + (f"; {h['not_recorded']} without the counters (written before they were stored)" if h["not_recorded"]
                else "") + ".", ""]
    if h["devices"]:
        lines += ["| device | " + " | ".join(c.replace("_", " ") for c in HEALTH_COUNTERS) + " |",
                  "|---" * (len(HEALTH_COUNTERS) + 1) + "|"]
        lines += [f"| {d} | " + " | ".join(str(c.get(k, "–")) for k in HEALTH_COUNTERS) + " |"
                  for d, c in h["devices"].items()]
    return lines + [""]


def write_markdown(path, r: dict, figures: list[str]) -> None:
    s = r["study"]
    inp = r.get("inputs", {})
    lines = ["# layerskin-exp report", ""] + _produced_by(r)
    lines += [f"Sessions: `{inp.get('sessions_dir')}` — {inp.get('files')} files, {inp.get('calibration_trials')} "
              f"calibration trials ({inp.get('press_trials')} press, {inp.get('slide_trials')} slide), "
              f"{inp.get('grip_trials')} grip trials. Skipped files: {inp.get('skipped') or 'none'}.", ""]
    lines += _stream_health(r)
    lines += _force(r, s) + _characterization(r, s) + _tracking(r, s) + _slip(r, s) + _slip_causal(r)
    if r.get("skipped"):
        lines += ["## Skipped sections", ""] + [f"- **{k}**: {v}" for k, v in r["skipped"].items()] + [""]
    if figures:
        lines += ["## Figures", ""] + [f"![{f}]({f})" for f in figures] + [""]
    Path(path).write_text("\n".join(lines))
