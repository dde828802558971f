"""Regenerate the finite-element reference data (layerskin_exp/sim/fem_reference/reference/).

    python -m layerskin_exp.sim.fem_reference            # both film-interface bounds (~30 min on 2 free cores)
    python -m layerskin_exp.sim.fem_reference --interface bonded

Per bound: the cap pressed in to DEPTHS_MM (frictionless), then, from SHEAR_FROM_MM,
sheared along +x with the contact sticking until the tangential force reaches SHEAR_RATIO of
the normal force (2 N at 6 N, the protocol's slide). Each equilibrium's forces, contact and
per-layer pressure profiles are written to reference/<bound>.npz; reference/summary.json lists the
scalars. The sim configuration is conf/sim/default.yaml's (`layerskin_exp.sim.config.load_sim`).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from layerskin_exp.sim.fem_reference.model import Section, StackFE

DATA = Path(__file__).resolve().parent / "reference"
DEPTHS_MM = (0.3, 0.6, 0.9, 1.2)
SHEAR_FROM_MM = (0.6, 0.9, 1.2)
SHEAR_RATIO = 2.0 / 6.0
SHEAR_STEP_MM = 0.1
SHEAR_MAX_MM = 1.0  # largest advance of the cap planned from one secant
SHEAR_INCREMENT_MM = 0.15
SCALARS = ("phase", "cap_x_mm", "depth_mm", "fx_n_per_mm", "fz_n_per_mm", "contact_from_mm", "contact_to_mm",
           "stuck_fraction", "sheet_shift_mm", "sheet_x_under_cap_mm", "max_lattice_strain", "newton_iterations", "branch_depth_mm")


def run_bound(sim, interface: str, log=print) -> dict:
    sec = Section.from_sim(sim, interface)
    fe = StackFE(sec)
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
            it = fe.move_to(np.array([0.0, top - depth]), sticking=False, step_mm=0.1)
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
                    it = fe.move_to(np.array([x_inc, c0[1]]), sticking=True, step_mm=SHEAR_INCREMENT_MM)
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
    out["superficial_x_mm"] = states[0]["superficial_x_mm"]
    out["deep_x_mm"] = states[0]["deep_x_mm"]
    out["contact_ref_x_mm"] = fe.mesh.points[fe.mesh.top_nodes, 0]
    for k in ("superficial_kpa", "deep_kpa", "contact_kpa", "contact_x_mm"):
        out[k] = np.stack([s[k] for s in states]).astype(np.float32)
    out["section"] = json.dumps(sec.__dict__)
    return out


def main(argv=None) -> int:
    from layerskin_exp.sim.config import load_sim

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--interface", choices=("bonded", "unbonded", "both"), default="both")
    ap.add_argument("--out", type=Path, default=DATA)
    args = ap.parse_args(argv)
    sim = load_sim([])
    args.out.mkdir(parents=True, exist_ok=True)
    bounds = ("bonded", "unbonded") if args.interface == "both" else (args.interface,)
    summary_path = args.out / "summary.json"
    summary = json.loads(summary_path.read_text()) if summary_path.exists() else {}
    for bound in bounds:
        t0 = time.time()
        res = run_bound(sim, bound)
        np.savez_compressed(args.out / f"{bound}.npz", **res)
        summary[bound] = {"seconds": round(time.time() - t0, 1),
                          "states": [{k: (None if not np.isfinite(res[k][i]) else round(float(res[k][i]), 5))
                                      for k in SCALARS} for i in range(len(res["phase"]))]}
        summary_path.write_text(json.dumps(summary, indent=1))
        print(f"{bound}: {len(res['phase'])} states in {time.time() - t0:.0f} s -> {args.out / (bound + '.npz')}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
