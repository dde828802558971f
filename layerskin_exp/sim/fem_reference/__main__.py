"""Regenerate the finite-element reference data (layerskin_exp/sim/fem_reference/reference/).

    python -m layerskin_exp.sim.fem_reference               # the section (~5 min on a free core)
    python -m layerskin_exp.sim.fem_reference --refinement  # + the same on a coarser and a finer mesh
    python -m layerskin_exp.sim.fem_reference --shear3d     # the 3D half-model's press and shear (shear3d.py):
        # to 0.3 and 0.6 mm and to 3 N (--shear3d-load), each sheared to F_x / F_z = 1/3, read
        # through the taxel grid beside the section (shear3d.json's count_signals)
    python -m layerskin_exp.sim.fem_reference --shear3d-refinement  # the 3D branch at 0.3 mm again on
        # a mesh halved under the cap (reference/refinement/shear3d.npz): shear3d_convergence.json
    python -m layerskin_exp.sim.fem_reference --shear3d-through-thickness  # the same branch with more
        # elements through the cover, the sheets and the lattice (refinement/shear3d_*.npz):
        # shear3d_through_thickness.json
    python -m layerskin_exp.sim.fem_reference --shear3d-load-branch  # the 3D branch at 3 N with a cover
        # that keeps its volume, pressed sticking, on the refined mesh (shear3d_load_branch.npz):
        # its tangential stiffness beside a closed form, shear3d_load_branch.json
    python -m layerskin_exp.sim.fem_reference --shear3d-mid-branch  # the same recipe at 0.83 N
        # (shear3d_mid_branch.npz and .json), the yardstick's middle state
    python -m layerskin_exp.sim.fem_reference --cover-poisson 0.499  # the section with a less
        # compressible cover (cover_poisson/): cover_compressibility.json
    python -m layerskin_exp.sim.fem_reference --homogenised-lattice  # the section with its lattice
        # homogenised inside the same solid rim (homogenised.npz) and out to the pad's sides
        # (homogenised_no_rim.npz, the 3D model's lattice), 50 s, beside the cells: homogenisation.json
    python -m layerskin_exp.sim.fem_reference --homogenised-refinement  # the homogenised section
        # (inside the rim) again on the doubled mesh (refinement/fine/homogenised.npz, ~35 min):
        # each gate signal's aligned mean on both meshes, homogenisation_convergence.json
    python -m layerskin_exp.sim.fem_reference --alignments  # the cap pressed in 0.5, 1, 1.5 mm from
        # the centre wall (alignment/, 7 min); `python -m layerskin_exp.sim.fem_reference.alignment`
        # prints each count-CoP shear signal over the alignments, FEM beside the fast model

The cap pressed in to DEPTHS_MM (frictionless), then, from SHEAR_FROM_MM, sheared along +x
with the contact sticking until the tangential force reaches SHEAR_RATIO of the normal force
(2 N at 6 N, the protocol's slide). Each equilibrium's forces, contact, per-layer pressure
profiles (with each node's tributary length: sum(p w) is the force the layer carries) and
moment balance are written to reference/bonded.npz; reference/summary.json lists the scalars
and, per state and layer, the load each layer's profile carries over F_z. `--refinement` solves
the same on Mesher's coarser and doubled meshes (reference/refinement/) and writes
reference/convergence.json: every compared quantity per mesh and its change between the two
finest. The sim configuration is conf/sim/default.yaml's (`layerskin_exp.sim.config.load_sim`).
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from layerskin_exp.sim.fem_reference.model import Mesher, Section, StackFE

DATA = Path(__file__).resolve().parent / "reference"
DEPTHS_MM = (0.3, 0.6, 0.9, 1.2)
# Shear branches start below the walls' buckling: from 0.9 mm (lattice strain 0.33, three times a
# bare wall's Euler strain pi^2/3 (w/H)^2 ~ 0.1) the section's path is not unique (on the default
# mesh F_x starts against the cap's travel, on the doubled one Newton stalls at 0.24 mm; from
# 1.2 mm both fail at the first step), so the comparison's shear rows stop at 0.6 mm.
SHEAR_FROM_MM = (0.3, 0.6)
SHEAR_RATIO = 2.0 / 6.0
SHEAR_STEP_MM = 0.1
SHEAR_MAX_MM = 1.0  # largest advance of the cap planned from one secant
SHEAR_INCREMENT_MM = 0.15
SCALARS = ("phase", "cap_x_mm", "depth_mm", "fx_n_per_mm", "fz_n_per_mm", "contact_from_mm", "contact_to_mm",
           "stuck_fraction", "sheet_shift_mm", "sheet_x_under_cap_mm", "max_lattice_strain", "newton_iterations", "branch_depth_mm",
           "load_x_mm", "load_height_mm")
# the node lines whose transmitted pressure is written: the superficial and deep Velostat cores'
# mid-planes (what each FSR reads), the lattice-to-deep-sheet interface and the base
LINES = ("superficial", "deep", "interface", "base")
BOUND = "bonded"
# the section with its lattice homogenised out to the pad's sides, no solid rim (the 3D model's lattice)
HOMOGENISED_NO_RIM = "homogenised_no_rim"
# a layer's profile must carry the cap's load: sum(p w) / F_z within this of 1
BALANCE_TOL = 0.02


def run_bound(sim, mesher: Mesher | None = None, log=print, homogenised: bool = False,
              cap_x0_mm: float = 0.0, cover_nu: float | None = None, rim: bool = True) -> dict:
    """The section's press and shear branches. cap_x0_mm: where the cap presses in, from the
    wall under the pad's centre (the walls stay where they are; `--alignments`); rim False with
    homogenised: no solid rim (Section.rim)."""
    interface = BOUND
    sec = replace(Section.from_sim(sim), homogenised=homogenised, cover_nu=cover_nu, rim=rim)
    mesher = mesher or Mesher()
    fe = StackFE(sec, mesher)
    states = []

    def record(phase: float, iters: int, branch: float):
        st = fe.state()
        st.update(phase=phase, newton_iterations=iters, branch_depth_mm=branch)
        states.append(st)
        log(f"  {interface} {'press' if phase == 0 else 'shear'} depth {st['depth_mm']:.2f} x {st['cap_x_mm']:.2f}: "
            f"Fz {st['fz_n_per_mm']:.4f} Fx {st['fx_n_per_mm']:.4f} N/mm, lattice strain {st['max_lattice_strain']:.2f}")
        return st

    top = fe.height_mm + sec.radius_mm
    saved = {}
    for depth in DEPTHS_MM:
        try:
            it = fe.move_to(np.array([cap_x0_mm, top - depth]), sticking=False, step_mm=0.1)
        except (RuntimeError, FloatingPointError, np.linalg.LinAlgError) as err:
            log(f"  {interface}: no equilibrium beyond depth {states[-1]['depth_mm']:.2f} mm ({err})")
            break
        record(0.0, it, np.nan)
        if any(abs(depth - d) < 1e-9 for d in SHEAR_FROM_MM):
            saved[depth] = (fe.u.copy(), fe.centre.copy())
    for depth, (u0, c0) in saved.items():
        fe.u[:] = u0
        fe.centre = c0.copy()
        fe.stick_all_in_contact()
        x, st = 0.0, None
        for _ in range(10):
            if st is None:
                x_next = SHEAR_STEP_MM
            else:  # the secant stiffness so far says how far the ratio still is (a little past it)
                k = st["fx_n_per_mm"] / x
                x_next = x + float(np.clip(1.05 * (SHEAR_RATIO * st["fz_n_per_mm"] - st["fx_n_per_mm"]) / k,
                                           SHEAR_STEP_MM, SHEAR_MAX_MM))
            # in increments of at most SHEAR_INCREMENT_MM, each recorded: where the section loses
            # equilibrium on the way, the states before it are kept
            n_inc = max(1, int(np.ceil((x_next - x - 1e-9) / SHEAR_INCREMENT_MM)))
            failed = False
            for x_inc in np.linspace(x, x_next, n_inc + 1)[1:]:
                try:
                    it = fe.move_to(np.array([cap_x0_mm + x_inc, c0[1]]), sticking=True, step_mm=SHEAR_INCREMENT_MM)
                except (RuntimeError, FloatingPointError, np.linalg.LinAlgError) as err:
                    log(f"  {interface}: shear from {depth} mm stopped at x {x_inc:.2f} ({err})")
                    failed = True
                    break
                x = float(x_inc)
                st = record(1.0, it, depth)
                if st["fx_n_per_mm"] >= SHEAR_RATIO * st["fz_n_per_mm"]:
                    break
            if failed or st["fx_n_per_mm"] >= SHEAR_RATIO * st["fz_n_per_mm"]:
                break
    out = {k: np.array([s[k] for s in states], dtype=float) for k in SCALARS}
    out["contact_ref_x_mm"] = fe.mesh.points[fe.mesh.top_nodes, 0]
    out["contact_w_mm"] = fe.mesh.top_weights
    for line in LINES:
        out[f"{line}_x_mm"] = states[0][f"{line}_x_mm"]
        out[f"{line}_w_mm"] = states[0][f"{line}_w_mm"]
        out[f"{line}_kpa"] = np.stack([s[f"{line}_kpa"] for s in states])
        out[f"{line}_shear_kpa"] = np.stack([s[f"{line}_shear_kpa"] for s in states]).astype(np.float32)
        out[f"{line}_moment_error"] = np.array([s[f"{line}_moment_error"] for s in states])
    for k in ("contact_kpa", "contact_x_mm"):
        out[k] = np.stack([s[k] for s in states])
    out["cap_start_mm"] = np.array(cap_x0_mm)
    out["section"] = json.dumps(sec.__dict__)
    out["mesher"] = json.dumps(mesher.__dict__)
    return require_balance(out, log)


def require_balance(res: dict, log=print) -> dict:
    """res, once every layer's profile carries F_z within BALANCE_TOL (else RuntimeError)."""
    worst = {line: float(np.abs(b - 1).max()) for line, b in balance(res).items()}
    log(f"  balance, worst |sum(p w) / F_z - 1| per layer: {worst}")
    if max(worst.values()) > BALANCE_TOL:
        raise RuntimeError(f"a layer's pressure does not carry the load: {worst} (allowed {BALANCE_TOL})")
    return res


def balance(res: dict) -> dict:
    """Per layer (and the cap's contact), sum(p w) / F_z for every state: the load each profile
    carries over the load applied. 1 when the pressures are the forces."""
    out = {}
    for line in (*LINES, "contact"):
        if f"{line}_kpa" not in res:
            continue
        carried = (np.asarray(res[f"{line}_kpa"], float) * np.asarray(res[f"{line}_w_mm"], float)).sum(axis=1) * 1e-3
        out[line] = carried / np.asarray(res["fz_n_per_mm"], float)
    return out


MESHES = {"coarse": Mesher(2, 3, 4, 1), "default": Mesher(), "fine": Mesher().finer()}
REFINEMENT = DATA / "refinement"


def solve(sim, mesh: str, out: Path) -> dict:
    """The section on one of MESHES, written to out/bonded.npz with out/summary.json beside it."""
    t0 = time.time()
    res = run_bound(sim, MESHES[mesh])
    out.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(out / f"{BOUND}.npz", **res)
    bal = balance(res)
    summary = {"mesh": mesh, "mesher": MESHES[mesh].__dict__, "seconds": round(time.time() - t0, 1),
               "states": [{**{k: (None if not np.isfinite(res[k][i]) else round(float(res[k][i]), 5)) for k in SCALARS},
                           "load_carried_over_fz": {line: round(float(b[i]), 6) for line, b in bal.items()},
                           "moment_error": {line: float(f"{res[line + '_moment_error'][i]:.2e}") for line in LINES}}
                          for i in range(len(res["phase"]))]}
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    print(f"{mesh}: {len(res['phase'])} states in {time.time() - t0:.0f} s -> {out / (BOUND + '.npz')}")
    return res


AXI_DEPTHS_MM = (0.1, 0.2, 0.3, 0.45, 0.6)
# what the section and the hemisphere (solid of revolution) are compared on, at equal cap depth
PLANE_STRAIN_DEPTHS_MM = (0.3, 0.6)


def run_axisymmetric(sim, log=print) -> dict:
    """The 3D check of the press: the same stack as a solid of revolution (walls as rings, the
    pad a disc of its half-width) under the hemisphere itself, pressed in frictionless. Shear
    breaks the symmetry: it is not solved here."""
    from layerskin_exp.sim.fem_reference.model import build_mesh

    sec = Section.from_sim(sim)
    fe = StackFE(sec, mesh=build_mesh(sec, Mesher(), axisymmetric=True))
    top = fe.height_mm + sec.radius_mm
    states = []
    with np.errstate(all="ignore"):  # the axis node carries no area: its pressure is undefined (nan)
        for depth in AXI_DEPTHS_MM:
            try:
                it = fe.move_to(np.array([0.0, top - depth]), sticking=False, step_mm=0.05)
            except (RuntimeError, FloatingPointError, np.linalg.LinAlgError) as err:
                log(f"  axisymmetric: no equilibrium beyond depth {states[-1]['depth_mm']:.2f} mm ({err})")
                break
            st = fe.state()
            st.update(phase=0.0, newton_iterations=it, branch_depth_mm=np.nan)
            states.append(st)
            log(f"  axisymmetric press depth {depth:.2f}: F {st['fz_n_per_mm']:.4f} N, contact radius "
                f"{st['contact_to_mm']:.3f} mm, lattice strain {st['max_lattice_strain']:.2f}")
    out = {k: np.array([s[k] for s in states], dtype=float) for k in SCALARS}
    out["contact_w_mm"] = fe.mesh.top_weights
    for line in LINES:
        out[f"{line}_x_mm"] = states[0][f"{line}_x_mm"]
        out[f"{line}_w_mm"] = states[0][f"{line}_w_mm"]  # ring areas, mm^2
        out[f"{line}_kpa"] = np.nan_to_num(np.stack([s[f"{line}_kpa"] for s in states]))  # the axis node: 0 x 0
    out["contact_kpa"] = np.nan_to_num(np.stack([s["contact_kpa"] for s in states]))
    out["contact_x_mm"] = np.stack([s["contact_x_mm"] for s in states])
    return require_balance(out, log)


def plane_strain_check(section: dict, axi: dict) -> dict:
    """The section (a cylinder, per mm) beside the hemisphere (a solid of revolution, N) at equal
    cap depths: contact half-width vs radius, peak superficial and deep pressures, the lattice's
    compression. Ratios are hemisphere / section."""
    rows = {}
    for depth in PLANE_STRAIN_DEPTHS_MM:
        i = np.flatnonzero((section["phase"] == 0) & np.isclose(section["depth_mm"], depth))
        j = np.flatnonzero(np.isclose(axi["depth_mm"], depth))
        if len(i) == 0 or len(j) == 0:
            continue
        i, j = int(i[0]), int(j[0])
        pairs = {
            "contact_half_width_mm": (0.5 * (section["contact_to_mm"][i] - section["contact_from_mm"][i]),
                                      axi["contact_to_mm"][j]),
            "peak_superficial_kpa": (section["superficial_kpa"][i].max(), axi["superficial_kpa"][j].max()),
            "peak_deep_kpa": (section["deep_kpa"][i].max(), axi["deep_kpa"][j].max()),
            "max_lattice_strain": (section["max_lattice_strain"][i], axi["max_lattice_strain"][j]),
        }
        rows[f"{depth:.2f} mm"] = {k: {"section": round(float(a), 5), "hemisphere": round(float(b), 5),
                                       "ratio": round(float(b / a), 4)} for k, (a, b) in pairs.items()}
        rows[f"{depth:.2f} mm"]["load"] = {"section_n_per_mm": round(float(section["fz_n_per_mm"][i]), 5),
                                           "hemisphere_n": round(float(axi["fz_n_per_mm"][j]), 5)}
    return rows


def homogenisation_check(cells: dict, hom: dict, sim) -> dict:
    """The section with its lattice as cells (the committed bonded.npz) beside the same section
    with the lattice homogenised (homogenised.npz; or homogenised_no_rim.npz, without the solid
    rim as well), on each quantity the fast model is compared on (compare.fem_side, through the
    simulator's FSR law): the error a homogenised lattice makes in each, measured in the
    reference itself. Differences are homogenised - cells."""
    from layerskin_exp.sim.fem_reference.compare import Reader, fem_side, line_model, line_sim

    reader = Reader(line_model(line_sim(sim, BOUND)))
    rows = {}
    for name, res in (("cells", cells), ("homogenised", hom)):
        branches = sorted(set(np.round(res["branch_depth_mm"][res["phase"] == 1], 6)))
        rows[name] = {f"{b:.1f} mm": r for b, r in zip(branches, fem_side(res, reader, branches), strict=True)}
    out = {}
    for branch, c in rows["cells"].items():
        h = rows["homogenised"].get(branch)
        if h is None:
            out[branch] = "not reached with the homogenised lattice"
            continue
        out[branch] = {k: {"cells": round(float(c[k]), 5), "homogenised": round(float(h[k]), 5),
                           "difference": round(float(h[k] - c[k]), 5),
                           "ratio": round(float(h[k] / c[k]), 4) if c[k] else None}
                       for k in c}
    return out


def homogenisation_convergence(default: dict, fine: dict, sim) -> dict:
    """The homogenised section's count-CoP shear signals (the gate's homogenised rows: aligned
    means over the taxel alignments) on the default and the doubled mesh, and their change: how
    far that yardstick is from converged. Both runs must balance their load."""
    from layerskin_exp.sim.fem_reference.alignment import taxel_aligned_means
    from layerskin_exp.sim.fem_reference.compare import line_model, line_sim

    model = line_model(line_sim(sim, BOUND))
    a, b = taxel_aligned_means(default, model), taxel_aligned_means(fine, model)
    out = {}
    for branch, d in a.items():
        f = b.get(branch)
        if f is None:
            out[f"{branch:.1f} mm"] = "not reached on the fine mesh"
            continue
        out[f"{branch:.1f} mm"] = {k: {"default": round(d[k], 5), "fine": round(f[k], 5),
                                       "change": round(f[k] - d[k], 5),
                                       "relative_change": round((f[k] - d[k]) / abs(d[k]), 4) if d[k] else None}
                                   for k in d}
    return out


def write_shear3d(res: dict, out: Path, seconds: float, sim=None) -> dict:
    """The 3D half-model's data (shear3d.npz) and its comparison (shear3d.json): beside the
    section per quantity (shear3d.plane_strain_shear), and its press beside the solid of
    revolution's at equal depth (axisymmetric.npz: resolved rings, so 3D / axisymmetric is the
    homogenised lattice's and the coarse 3D mesh's error together)."""
    from layerskin_exp.sim.fem_reference.shear3d import count_signals_vs_section, plane_strain_shear

    np.savez_compressed(out / "shear3d.npz", **res)
    axi = dict(np.load(out / "axisymmetric.npz"))
    press = {}
    for depth in PLANE_STRAIN_DEPTHS_MM:
        i = np.flatnonzero((res["phase"] == 0) & np.isclose(res["depth_mm"], depth))
        j = np.flatnonzero(np.isclose(axi["depth_mm"], depth))
        if len(i) == 0 or len(j) == 0:
            continue
        i, j = int(i[0]), int(j[0])
        pairs = {"load_n": (axi["fz_n_per_mm"][j], res["fz_n"][i]),
                 "contact_radius_mm": (axi["contact_to_mm"][j], 0.5 * (res["contact_to_mm"][i] - res["contact_from_mm"][i])),
                 "peak_superficial_kpa": (axi["superficial_kpa"][j].max(), res["superficial_kpa"][i].max()),
                 "peak_deep_kpa": (axi["deep_kpa"][j].max(), res["deep_kpa"][i].max()),
                 "max_lattice_strain": (axi["max_lattice_strain"][j], res["max_lattice_strain"][i])}
        press[f"{depth:.2f} mm"] = {k: {"axisymmetric": round(float(a), 5), "3d": round(float(b), 5), "ratio": round(float(b / a), 4)}
                                    for k, (a, b) in pairs.items()}
    keys = [k for k in res if np.ndim(res[k]) == 1 and len(res[k]) == len(res["phase"])]
    check = {"seconds": round(seconds, 1), "dof": int(res["dof"]), "factorisations": int(res["factorisations"]),
             "factor_cpu_seconds": round(float(res["factor_seconds"]), 1),
             "depths": plane_strain_shear(dict(np.load(out / f"{BOUND}.npz")), res),
             "press_vs_axisymmetric": press,
             "count_signals": None if sim is None else count_signals_vs_section(res, sim, out),
             "stopped": json.loads(str(res.get("stopped", "{}"))),
             "states": [{k: (None if not np.isfinite(res[k][i]) else round(float(res[k][i]), 5)) for k in keys}
                        for i in range(len(res["phase"]))]}
    (out / "shear3d.json").write_text(json.dumps(check, indent=1))
    return check


def _write_study(path: Path, t0: float, body: dict) -> dict:
    """A study's record: its wall time since t0, then body; written to path as JSON and printed."""
    check = {"seconds": round(time.time() - t0, 1), **body}
    path.write_text(json.dumps(check, indent=1))
    print(json.dumps(check, indent=1))
    return check


def main(argv=None) -> int:
    from layerskin_exp.sim.config import load_sim

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mesh", choices=tuple(MESHES), default="default",
                    help="solve on this mesh only (default: the committed data's)")
    ap.add_argument("--refinement", action="store_true",
                    help="solve on every mesh and write reference/convergence.json")
    ap.add_argument("--axisymmetric", action="store_true",
                    help="the hemisphere's press as a solid of revolution (the 3D check), beside the section")
    ap.add_argument("--shear3d", action="store_true",
                    help="the hemisphere's press and shear as a 3D half-model (homogenised lattice), beside the section")
    ap.add_argument("--shear3d-load", type=float, nargs="*", default=None, metavar="N",
                    help="with --shear3d: the whole skin's normal loads (N) the 3D model is also pressed to and "
                         "sheared from (default: shear3d.LOADS_N; none given: the depths only)")
    ap.add_argument("--shear3d-refinement", action="store_true",
                    help="the 3D branch pressed to shear3d.REFINEMENT_DEPTH_MM again on the refined mesh "
                         "(reference/refinement/shear3d.npz) beside the committed one: reference/shear3d_convergence.json")
    ap.add_argument("--shear3d-through-thickness", action="store_true",
                    help="the 3D branch pressed to shear3d.REFINEMENT_DEPTH_MM again with more elements through the "
                         "layers' thickness (shear3d.THROUGH_THICKNESS; reference/refinement/shear3d_*.npz) beside the "
                         "committed one: "
                         "reference/shear3d_through_thickness.json")
    ap.add_argument("--shear3d-load-branch", action="store_true",
                    help="the 3D model pressed to the study's load with shear3d.LOAD_BRANCH's cover, contact and mesh "
                         "and sheared sticking (reference/shear3d_load_branch.npz): its tangential stiffness beside the "
                         "series closed form, reference/shear3d_load_branch.json")
    ap.add_argument("--shear3d-mid-branch", action="store_true",
                    help="the load branch's recipe at 0.83 N (shear3d.MID_BRANCH): reference/shear3d_mid_branch.npz "
                         "and .json, the yardstick's middle state")
    ap.add_argument("--stiff-cover", action="store_true",
                    help="the load branch again for the design at the stiff end of the cover's bracket "
                         "(shear3d.STIFF_COVER_KPA, a Dragon Skin / Sil-Poxy class silicone): "
                         "reference/shear3d_stiff_cover.npz and .json, the yardstick's second design")
    ap.add_argument("--shear3d-squeeze", action="store_true",
                    help="the 3D model's 0.3 mm branch on the committed mesh, its mid-plane reading against its "
                         "faces' mean and the films' squeeze from its own deflection (shear3d.squeeze3d): "
                         "reference/shear3d_squeeze.json, ~8 min")
    ap.add_argument("--shear3d-diagonal", action="store_true",
                    help="the whole pad pressed to 0.3 mm and sheared along x and along the diagonal (shear3d.diagonal3d): "
                         "reference/shear3d_diagonal.json")
    ap.add_argument("--alignments", action="store_true",
                    help="the section with the cap pressed in at alignment.ALIGN_X0_MM from the centre wall "
                         "(reference/alignment/x0_*.npz): a campaign presses at every alignment")
    ap.add_argument("--homogenised-lattice", action="store_true",
                    help="the section again with its lattice homogenised inside the solid rim (reference/homogenised.npz) "
                         "and out to the pad's sides (reference/homogenised_no_rim.npz), and reference/homogenisation.json: "
                         "what the cells, and the rim, do to each compared quantity")
    ap.add_argument("--homogenised-refinement", action="store_true",
                    help="the homogenised section (inside the solid rim) again on the doubled mesh "
                         "(reference/refinement/fine/homogenised.npz) and reference/homogenisation_convergence.json: "
                         "each gate signal's aligned mean on both meshes")
    ap.add_argument("--cover-poisson", type=float, nargs="+", default=None, metavar="NU",
                    help="the section again with the cover's Poisson ratio NU (reference/cover_poisson/nu_*.npz) and "
                         "reference/cover_compressibility.json: what the cover's assumed compressibility does to each "
                         "compared quantity")
    ap.add_argument("--convergence-only", action="store_true",
                    help="recompute reference/convergence.json from the data already there")
    ap.add_argument("--out", type=Path, default=None, help="output folder (default: the package's reference/)")
    args = ap.parse_args(argv)
    sim = load_sim([])
    if not (args.convergence_only or args.axisymmetric or args.shear3d or args.shear3d_refinement or args.homogenised_lattice
            or args.alignments or args.shear3d_through_thickness or args.cover_poisson or args.shear3d_load_branch
            or args.stiff_cover or args.shear3d_mid_branch or args.shear3d_squeeze or args.shear3d_diagonal
            or args.homogenised_refinement):
        meshes = tuple(MESHES) if args.refinement else (args.mesh,)
        for mesh in meshes:
            out = args.out or (DATA if mesh == "default" else REFINEMENT / mesh)
            solve(sim, mesh, out)
    if args.axisymmetric:
        t0 = time.time()
        out = args.out or DATA
        axi = run_axisymmetric(sim)
        np.savez_compressed(out / "axisymmetric.npz", **axi)
        check = {"seconds": round(time.time() - t0, 1), "depths": plane_strain_check(dict(np.load(out / f"{BOUND}.npz")), axi),
                 "states": [{k: (None if not np.isfinite(axi[k][i]) else round(float(axi[k][i]), 5)) for k in SCALARS}
                            for i in range(len(axi["phase"]))]}
        (out / "plane_strain.json").write_text(json.dumps(check, indent=1))
        print(json.dumps(check["depths"], indent=1))
    if args.alignments:
        from layerskin_exp.sim.fem_reference.alignment import ALIGN_X0_MM

        folder = (args.out or DATA) / "alignment"
        folder.mkdir(parents=True, exist_ok=True)
        for x0 in ALIGN_X0_MM[1:]:  # 0 is the committed section (bonded.npz)
            t0 = time.time()
            res = run_bound(sim, MESHES["default"], cap_x0_mm=x0)
            np.savez_compressed(folder / f"x0_{x0:.2f}.npz", **res)
            print(f"cap at {x0:.2f} mm: {len(res['phase'])} states in {time.time() - t0:.0f} s")
    if args.homogenised_lattice:
        t0 = time.time()
        out = args.out or DATA
        cells = dict(np.load(out / f"{BOUND}.npz"))
        hom = run_bound(sim, MESHES["default"], homogenised=True)
        require_balance(hom)
        np.savez_compressed(out / "homogenised.npz", **hom)
        bare = run_bound(sim, MESHES["default"], homogenised=True, rim=False)
        require_balance(bare)
        np.savez_compressed(out / f"{HOMOGENISED_NO_RIM}.npz", **bare)
        _write_study(out / "homogenisation.json", t0,
                     {"branches": homogenisation_check(cells, hom, sim),
                      "without_rim": homogenisation_check(cells, bare, sim)})
    if args.homogenised_refinement:
        t0 = time.time()
        out = args.out or DATA
        fine = run_bound(sim, MESHES["fine"], homogenised=True)
        require_balance(fine)
        (out / "refinement" / "fine").mkdir(parents=True, exist_ok=True)
        np.savez_compressed(out / "refinement" / "fine" / "homogenised.npz", **fine)
        _write_study(out / "homogenisation_convergence.json", t0,
                     {"branches": homogenisation_convergence(dict(np.load(out / "homogenised.npz")), fine, sim)})
    if args.shear3d:
        from layerskin_exp.sim.fem_reference.shear3d import LOADS_N, run_shear3d

        t0 = time.time()
        out = args.out or DATA
        loads = LOADS_N if args.shear3d_load is None else tuple(args.shear3d_load)
        res = run_shear3d(sim, loads_n=loads, partial=lambda r: write_shear3d(r, out, time.time() - t0, sim))
        check = write_shear3d(res, out, time.time() - t0, sim)
        print(json.dumps({k: check[k] for k in ("depths", "count_signals", "stopped")}, indent=1))
    if args.shear3d_refinement:
        from layerskin_exp.sim.fem_reference import shear3d as s3

        t0 = time.time()
        out = args.out or DATA
        (out / "refinement").mkdir(parents=True, exist_ok=True)
        fine = s3.run_shear3d(sim, x_edges=s3.REFINED_X_EDGES_MM, y_edges=s3.REFINED_Y_EDGES_MM,
                              depths=(s3.REFINEMENT_DEPTH_MM,), loads_n=())
        np.savez_compressed(out / "refinement" / "shear3d.npz", **fine)
        _write_study(out / "shear3d_convergence.json", t0,
                     s3.refinement3d(dict(np.load(out / "shear3d.npz")), fine, sim, data=out))
    if args.cover_poisson:
        from layerskin_exp.sim.fem_reference.convergence import cover_compressibility

        t0 = time.time()
        out = args.out or DATA
        folder = out / "cover_poisson"
        folder.mkdir(parents=True, exist_ok=True)
        for nu in args.cover_poisson:
            res = run_bound(sim, MESHES["default"], cover_nu=nu)
            np.savez_compressed(folder / f"nu_{nu:.4f}.npz", **res)
        _write_study(out / "cover_compressibility.json", t0, cover_compressibility(sim, args.cover_poisson, out))
    if args.shear3d_through_thickness:
        from layerskin_exp.sim.fem_reference import shear3d as s3

        t0 = time.time()
        out = args.out or DATA
        (out / "refinement").mkdir(parents=True, exist_ok=True)
        by_name = {}
        for name, elements in s3.THROUGH_THICKNESS.items():
            by_name[name] = s3.run_shear3d(sim, depths=(s3.REFINEMENT_DEPTH_MM,), loads_n=(), elements=elements)
            np.savez_compressed(out / "refinement" / f"shear3d_{name}.npz", **by_name[name])
        _write_study(out / "shear3d_through_thickness.json", t0,
                     s3.through_thickness3d(dict(np.load(out / "shear3d.npz")), by_name, sim, data=out))
    for wanted, recipe, name in ((args.shear3d_load_branch, "LOAD_BRANCH", "shear3d_load_branch"),
                                 (args.shear3d_mid_branch, "MID_BRANCH", "shear3d_mid_branch")):
        if not wanted:
            continue
        from layerskin_exp.sim.fem_reference import shear3d as s3

        t0 = time.time()
        out = args.out or DATA
        res = s3.run_shear3d(sim, depths=(), **getattr(s3, recipe))
        np.savez_compressed(out / f"{name}.npz", **res)
        _write_study(out / f"{name}.json", t0, {"dof": int(res["dof"]), "stopped": json.loads(str(res["stopped"])),
                                                "branches": s3.load_branch3d(res)})
    if args.shear3d_load_branch:
        from layerskin_exp.sim.fem_reference import shear3d as s3
        from layerskin_exp.sim.fem_reference.compare import load_tolerances, table

        print(table(s3.load_branch_rows(sim, load_tolerances(), args.out or DATA)))  # the fast model beside it (not gated)
    if args.stiff_cover:
        from layerskin_exp.sim.fem_reference import shear3d as s3

        t0 = time.time()
        out = args.out or DATA
        res = s3.run_shear3d(s3.stiff_cover_sim(sim), depths=(), partial=lambda r: np.savez_compressed(
            out / "shear3d_stiff_cover.npz", **r), **s3.LOAD_BRANCH)
        np.savez_compressed(out / "shear3d_stiff_cover.npz", **res)
        _write_study(out / "shear3d_stiff_cover.json", t0, {"cover_modulus_kpa": s3.STIFF_COVER_KPA, "dof": int(res["dof"]),
                                                            "stopped": json.loads(str(res["stopped"])),
                                                            "branches": s3.load_branch3d(res)})
    if args.shear3d_squeeze:
        from layerskin_exp.sim.fem_reference import shear3d as s3

        t0 = time.time()
        _write_study((args.out or DATA) / "shear3d_squeeze.json", t0, s3.squeeze3d(sim))
    if args.shear3d_diagonal:
        from layerskin_exp.sim.fem_reference import shear3d as s3

        t0 = time.time()
        _write_study((args.out or DATA) / "shear3d_diagonal.json", t0, s3.diagonal3d(sim))
    if args.refinement or args.convergence_only:
        from layerskin_exp.sim.fem_reference.convergence import write_convergence

        print(write_convergence(sim))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
