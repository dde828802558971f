"""`make demo`: the main job on the simulated rig, end to end.

1. a reduced force-calibration campaign (platform + indenter + Mini40, virtual clock), and beside
   it, on the other core, a reduced grip-depth x trajectory multirun (UR5e + Hand-E + rod +
   camera; its console output goes to <out>/grip_depth.log),
2. the analysis report on the session files both wrote,
then prints where everything is. Each stage is the same command a user would type, so the demo
also shows how to run them. Re-running resumes: complete trials are not simulated again (the
sessions go under <out>/sessions/simulator-<code>, one folder per version of the simulator, so a
changed simulator simulates afresh and the report reads only its own sessions).
Both simulations run one process each (a campaign is one process; the grip multirun runs its jobs
one after the other, so the contact tables and kernels load once), so on two cores they take the
time of the longer, not the sum.

    python -m layerskin_exp.demo [--out DIR] [--positions N] [--grip-trials N]
"""

from __future__ import annotations

import argparse
import json
import shlex
import subprocess
import sys
import time
from pathlib import Path


def _announce(title: str, args: list[str], where: str = "") -> None:
    print(f"\n== {title}{where}\n$ python {shlex.join(args)}", flush=True)


def _run(title: str, args: list[str]) -> float:
    _announce(title, args)
    t0 = time.perf_counter()
    rc = subprocess.call([sys.executable, *args])
    dt = time.perf_counter() - t0
    if rc != 0:
        raise SystemExit(f"demo: stage '{title}' failed with exit code {rc}; see the output above")
    print(f"-- {title}: {dt:.1f} s", flush=True)
    return dt


class _Background:
    """A stage run beside the foreground one, its console output in a log file."""

    def __init__(self, title: str, args: list[str], log_path: Path) -> None:
        self.title, self.log_path = title, log_path
        _announce(title, args, f" (beside the next stage; output in {log_path})")
        log_path.parent.mkdir(parents=True, exist_ok=True)
        self._log = log_path.open("w")
        self.t0 = time.perf_counter()
        self.proc = subprocess.Popen([sys.executable, *args], stdout=self._log, stderr=subprocess.STDOUT)

    def wait(self) -> float:
        if self.proc.poll() is None:
            print(f"\n.. waiting for: {self.title}", flush=True)
        rc = self.proc.wait()
        dt = time.perf_counter() - self.t0
        self._log.close()
        if rc != 0:
            tail = self.log_path.read_text(errors="replace").splitlines()[-15:]
            raise SystemExit(f"demo: stage '{self.title}' failed with exit code {rc}; the end of "
                             f"{self.log_path}:\n" + "\n".join(tail))
        print(f"-- {self.title}: {dt:.1f} s", flush=True)
        return dt

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            self.proc.wait()
        self._log.close()


def _signed(x) -> str:
    return "–" if x is None else f"{x:+.3f}"


def force_summary(results_path: Path) -> str:
    """The force table (R² per axis, ours and the study's), each CNN's gain over the linear
    baseline with its confidence interval, and each CNN's training verdict, from the report's
    results.json."""
    r = json.loads(results_path.read_text())
    force, study, training = r.get("force") or {}, r["study"]["force"], r.get("force_training") or {}
    if not force:
        return "force estimation skipped: " + str(r.get("skipped", {}).get("force", "no result"))
    models = list(force)
    lines = ["R² (study's in brackets)".ljust(26) + "".join(m.rjust(18) for m in models)]
    for ax in ("Fx", "Fy", "Fz"):
        cells = []
        for m in models:
            ours, theirs = force[m][ax]["r2"], study.get(m, {}).get(ax, {}).get("r2")
            cells.append((("–" if ours is None else f"{ours:.3f}") + (f" ({theirs:.3f})" if theirs else "")).rjust(18))
        lines.append(f"  {ax}".ljust(26) + "".join(cells))
    gains = r.get("force_gain_over_linear") or {}
    for m in models:
        if m in gains:
            pct = round(100 * gains["confidence"])
            n_test, n_min = r["force_split"]["test_trials"], gains.get("min_test_trials")
            lines.append(f"{m} minus linear, R² ({pct} % CI over the {n_test} test trials"
                         + (f"; undefined below {n_min}" if n_min else "") + "): "
                         + ", ".join(f"{ax} {_signed(g)} " + ("[undefined]" if lo is None or hi is None
                                                              else f"[{_signed(lo)}, {_signed(hi)}]")
                                     for ax, (g, lo, hi) in gains[m].items()))
    for m, t in training.items():
        verdict = ("converged" if t.get("converged") else "NOT CONVERGED: " + "; ".join(t.get("caveats", [])))
        lines.append(f"{m}: {t['epochs']}/{t['max_epochs']} epochs, best at {t['best_epoch']}, "
                     f"early stopping {'triggered' if t['early_stopped'] else 'not triggered'}: {verdict}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default="demo_out", help="folder for session files and the report")
    ap.add_argument("--positions", type=int, default=64,
                    help="contact positions of the calibration campaign (on 32, T-s5 fits its 202 training "
                         "trials and its test R² depends on the split; see conf/analysis/demo.yaml)")
    ap.add_argument("--grip-trials", type=int, default=3, help="trials per grip depth and motion")
    ap.add_argument("--jobs", type=int, default=1,
                    help="parallel grip trials (joblib launcher when > 1; the default runs them one after "
                         "the other beside the calibration campaign)")
    a = ap.parse_args(argv)

    out = Path(a.out).resolve()
    # one data root per simulator version: a rerun resumes its own sessions, and the report never
    # mixes sessions that another version of the simulator made (those stay where they are)
    from layerskin_exp.sim.table_cache import simulator_version  # the simulator: not for --help

    data = out / "sessions" / f"simulator-{simulator_version()}"
    report = out / "report"
    timings = {}
    launcher = ["hydra/launcher=joblib", f"hydra.launcher.n_jobs={a.jobs}"] if a.jobs > 1 else []
    grip = _Background(
        f"grip-depth multirun: g = 6, 9, 12, 15 mm x translation, torsion x {a.grip_trials} trials",
        ["-m", "protocols.grip_depth", "-m", "grip_depth=6,9,12,15", "trajectory=translation,torsion",
         f"trial=range({a.grip_trials})", f"data_root={data}", *launcher, "progress=false",
         f"hydra.sweep.dir={out}/hydra/grip_depth"],
        out / "grip_depth.log",
    )
    try:
        timings["calibration"] = _run(
            f"force-calibration campaign: {a.positions} positions x (5 presses + 4 slides)",
            ["-m", "protocols.force_calibration", f"data_root={data}", f"positions.count={a.positions}",
             f"hydra.run.dir={out}/hydra/force_calibration"],
        )
        timings["grip"] = grip.wait()
    finally:
        grip.stop()
    timings["report"] = _run(
        "analysis report (analysis=demo preset)",
        ["-m", "analysis.report", f"sessions={data}", f"out={report}", "analysis=demo"],
    )
    print("\n== force estimation on the held-out calibration trials (report.md has every table)")
    print(force_summary(report / "results.json"))
    print("\n== done")
    print(f"session files: {data}  (inspect one: python -m layerskin_exp.log inspect FILE)")
    print(f"report:        {report / 'report.md'}")
    print(f"results:       {report / 'results.json'}")
    print("wall time:     " + ", ".join(f"{k} {v:.0f} s" for k, v in timings.items())
          + " (calibration and grip side by side)")


if __name__ == "__main__":
    main()
