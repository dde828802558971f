"""No module is imported once a trial's acquisition has started.

Importing a module holds the interpreter lock for its whole body; a heavy one (foxglove.layouts:
~35 ms) imported lazily at a trial's close starved the loopback emulators, which run in the same
process, past their 50 ms stream deadlines at the next trial. The probe runs a protocol with an
audit hook that notes every import after the first session file is opened."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from tests.protocols.conftest import REPO, TINY_GRIP

PROBE = """
import runpy, sys
started, late = [], []
def hook(event, args):
    if event == "open" and str(args[0]).endswith(".mcap.partial"):
        started.append(1)
    elif event == "import" and started and args[0] not in sys.modules:
        late.append(args[0])
sys.addaudithook(hook)
module, sys.argv = sys.argv[1], [sys.argv[1], *sys.argv[2:]]
try:
    runpy.run_module(module, run_name="__main__")
except SystemExit as e:
    if e.code:
        raise
print("PROBE", len(started), sorted(set(late)))
"""

CASES = {
    "protocols.force_calibration": ["positions.count=1", "press.repeats=1", "slide.repeats=1", "press.hold_s=0.05"],
    "protocols.grip_depth": TINY_GRIP,
}


@pytest.mark.parametrize("module", list(CASES))
def test_no_import_after_acquisition_starts(tmp_path, hydra_dirs, module):
    args = ["hardware=sim", *CASES[module], "progress=false", f"data_root={tmp_path / 'data'}", *hydra_dirs]
    env = {**os.environ, "PYTHONPATH": str(REPO), "HYDRA_FULL_ERROR": "0"}
    r = subprocess.run([sys.executable, "-c", PROBE, module, *args], cwd=tmp_path, env=env, capture_output=True,
                       text=True, timeout=240)
    assert r.returncode == 0, r.stderr[-3000:]
    (line,) = [ln for ln in r.stdout.splitlines() if ln.startswith("PROBE")]
    n_files, late = line.split(" ", 2)[1:]
    assert int(n_files) >= 1, "the probe never saw a session file opened"
    assert late == "[]", f"modules imported during acquisition: {late}"
