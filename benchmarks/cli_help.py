"""How soon the protocols' command line answers: `python -m protocols.grip_depth --help`, a refused
override (`grip_depth=abc`, exit 2) and `--cfg job` (and the same three of the simulator's preview
and validation), each a fresh process timed by its wall clock,
against a bare `python -c pass` in the same run (the interpreter's own start).

Target (issue 32): each under 1.5 s on 2 cores. Before the heavy imports moved to where they are
used, --help took 6.5-7.3 s and imported 1,106 modules (numba, cv2, scipy, mcap, foxglove): the
schemas reached `layerskin_exp.vision`'s numba kernels through `hardware.camera`'s package file, and
Hydra's own --help copied the whole config repository for each of ~100 config groups it listed.
The module count and any heavy module still imported come from one `-X importtime` run.
Issue 52: the same answers of the report and the design map (3.5-4.2 s while their modules loaded
torch and scikit-learn at the top).

    python -m benchmarks.cli_help                 # 5 runs of each, median and best
    python -m benchmarks.cli_help --repo /tmp/old-checkout   # another checkout's code, same baseline
    python -m benchmarks.cli_help --repo /tmp/old-checkout --repo .   # both, interleaved in one run
    python -m benchmarks.run cli_help
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
COMMANDS = {
    "help": ["-m", "protocols.grip_depth", "--help"],
    "refused_override": ["-m", "protocols.grip_depth", "grip_depth=abc"],
    "cfg_job": ["-m", "protocols.grip_depth", "--cfg", "job"],
    # the simulator's preview and validation, Hydra apps through the same entry (layerskin_exp.cli)
    "preview_help": ["-m", "layerskin_exp.sim.preview", "--help"],
    "preview_refused_override": ["-m", "layerskin_exp.sim.preview", "seed=abc"],
    "preview_cfg_job": ["-m", "layerskin_exp.sim.preview", "--cfg", "job"],
    "validate_help": ["-m", "layerskin_exp.sim.validate", "--help"],
    "validate_refused_override": ["-m", "layerskin_exp.sim.validate", "sim.spacer.modulus_kpa=abc"],
    "validate_cfg_job": ["-m", "layerskin_exp.sim.validate", "--cfg", "job"],
    # the report and the design map: Hydra apps whose runs need torch and scikit-learn
    "report_help": ["-m", "analysis.report", "--help"],
    "report_refused_sessions": ["-m", "analysis.report", "sessions=nowhere"],
    "design_map_help": ["-m", "analysis.design_map", "--help"],
    "design_map_refused_override": ["-m", "analysis.design_map", "bogus=1"],
    # every other command's --help
    "calibration_help": ["-m", "protocols.force_calibration", "--help"],
    "sensitivity_help": ["-m", "protocols.sensitivity", "--help"],
    "design_search_help": ["-m", "protocols.design_search", "--help"],
    "sessions_help": ["-m", "protocols.sessions", "--help"],
    "log_help": ["-m", "layerskin_exp.log", "--help"],
    "export_help": ["-m", "layerskin_exp.estimation.export", "--help"],
    "emulate_help": ["-m", "hardware.emulate", "--help"],
    "demo_help": ["-m", "layerskin_exp.demo", "--help"],
}
BASELINE = ["-c", "pass"]
HEAVY = ("numba", "cv2", "scipy", "torch", "mcap", "foxglove", "matplotlib")


def _wall_s(args: list[str], repo: Path) -> float:
    env = {**os.environ, "PYTHONPATH": str(repo)}
    t0 = time.perf_counter()
    subprocess.run([sys.executable, *args], cwd=repo, env=env, stdout=subprocess.DEVNULL,
                   stderr=subprocess.DEVNULL, check=False)
    return time.perf_counter() - t0


def _imported(args: list[str], repo: Path) -> list[str]:
    """Every module the command imports (`-X importtime` lists each once)."""
    env = {**os.environ, "PYTHONPATH": str(repo)}
    r = subprocess.run([sys.executable, "-X", "importtime", *args], cwd=repo, env=env, capture_output=True,
                       text=True, check=False)
    return [ln.rsplit("|", 1)[1].strip() for ln in r.stderr.splitlines() if ln.startswith("import time:")
            and not ln.rstrip().endswith("| package")]


def run(repeats: int = 5, repo: Path = REPO) -> dict:
    return compare(repeats, [repo])[str(repo)]


def compare(repeats: int, repos: list[Path]) -> dict[str, dict]:
    """The figures of each checkout, measured in one run: every repeat times each command in each
    checkout in turn (interleaved, so that load from elsewhere on the machine falls on all alike)."""
    walls = {str(r): {name: [] for name in ["python_pass", *COMMANDS]} for r in repos}
    for _ in range(repeats):
        for name, args in [("python_pass", BASELINE), *COMMANDS.items()]:
            for r in repos:
                walls[str(r)][name].append(_wall_s(args, r))
    results = {}
    for r in repos:
        w = walls[str(r)]
        out = {f"{name}_s": {"median": round(statistics.median(v), 3), "best": round(min(v), 3)}
               for name, v in w.items()}
        base = statistics.median(w["python_pass"])
        for name in COMMANDS:
            out[f"{name}_minus_pass_s"] = round(statistics.median(w[name]) - base, 3)
        modules = _imported(COMMANDS["help"], r)
        out["help_modules"] = len(modules)
        out["help_heavy_modules"] = sorted({m.split(".")[0] for m in modules} & set(HEAVY))
        for app in ("preview", "validate"):
            modules = _imported(COMMANDS[f"{app}_help"], r)
            out[f"{app}_help_modules"] = len(modules)
            out[f"{app}_help_heavy_modules"] = sorted({m.split(".")[0] for m in modules} & set(HEAVY))
        out["repeats"] = repeats
        results[str(r)] = out
    return results


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.cli_help", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--repo", type=Path, action="append",
                        help="the checkout whose commands are timed (default this one); given twice, "
                             "both are timed in one interleaved run, side by side")
    args = parser.parse_args(argv)
    repos = [r.resolve() for r in (args.repo or [REPO])]
    results = compare(args.repeats, repos)
    if len(repos) == 1:
        for key, value in results[str(repos[0])].items():
            print(f"{key:<42} {value}")
        return 0
    print(f"{'':<42} " + "  ".join(f"{str(r):<34}" for r in repos))
    for key in results[str(repos[0])]:
        print(f"{key:<42} " + "  ".join(f"{str(results[str(r)][key]):<34}" for r in repos))
    return 0


if __name__ == "__main__":
    sys.exit(main())
