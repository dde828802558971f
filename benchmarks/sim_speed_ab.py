"""The simulated rig's speed before and after a change, in the same run.

    python -m benchmarks.sim_speed_ab [REF] [--rounds N]

Checks REF (a git revision, default HEAD~1) out into a temporary worktree and times
`benchmarks.sim_speed`'s calibration trial and grip trial (10 ms control ticks, camera rendering)
with that tree's code and with the checkout's, in fresh processes, alternating the two so that
both see the same load on a shared machine; reports each side's median speed (simulated seconds
per wall second) and the ratio after / before. Each process warms the compiled kernels on a short
trial first (their on-disk cache is per tree), so compilation is not timed. `run()` (for
`benchmarks.run`) compares against HEAD~1 with 3 rounds.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
_PROBE = """
import json, time
from benchmarks.sim_speed import calibration_trial, grip_trial
calibration_trial(seed=9); grip_trial(seed=9)
c_sim, c_wall, _ = calibration_trial()
g_sim, g_wall, _, _ = grip_trial()
print(json.dumps({"calibration_x_realtime": c_sim / c_wall, "grip_x_realtime": g_sim / g_wall}))
"""


def _probe(tree: Path) -> dict:
    env = {**os.environ, "PYTHONPATH": str(tree)}
    out = subprocess.run([sys.executable, "-c", _PROBE], cwd=tree, env=env, capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def compare(ref: str = "HEAD~1", rounds: int = 3) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        before_tree = Path(tmp) / "before"
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", "-q", str(before_tree), ref], check=True)
        try:
            runs: dict[str, list[dict]] = {"before": [], "after": []}
            for _ in range(rounds):
                runs["before"].append(_probe(before_tree))
                runs["after"].append(_probe(ROOT))
        finally:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(before_tree)], check=False)
    out: dict = {"ref": ref, "rounds": rounds}
    for key in ("calibration_x_realtime", "grip_x_realtime"):
        b = sorted(r[key] for r in runs["before"])[rounds // 2]
        a = sorted(r[key] for r in runs["after"])[rounds // 2]
        out[f"{key}_before"], out[f"{key}_after"], out[f"{key}_after_over_before"] = b, a, a / b
    return out


def run() -> dict:
    return compare()


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("ref", nargs="?", default="HEAD~1")
    ap.add_argument("--rounds", type=int, default=3)
    a = ap.parse_args()
    for k, v in compare(a.ref, a.rounds).items():
        print(f"{k}: {v:.4g}" if isinstance(v, float) else f"{k}: {v}")
