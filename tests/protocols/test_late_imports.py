"""No module is imported once the devices stream.

Importing a module holds the interpreter lock for much of its body; a heavy one (foxglove.layouts:
~35 ms) imported lazily at a trial's close starved the loopback emulators, which run in the same
process, past their 50 ms stream deadlines at the next trial. The probe runs a protocol with an
audit hook that notes every import after the app's "layerskin_exp.rig_connected" audit event."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from tests.protocols.conftest import REPO, TINY_GRIP
from tests.protocols.test_grip_estimate import _artifact

PROBE = """
import runpy, sys
started, late = [], []
def hook(event, args):
    if event == "layerskin_exp.rig_connected":
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
    "calibration": ("protocols.force_calibration",
                    ["positions.count=1", "press.repeats=1", "slide.repeats=1", "press.hold_s=0.05"]),
    "grip": ("protocols.grip_depth", TINY_GRIP),
    "grip with a live estimator": ("protocols.grip_depth", TINY_GRIP),
}


@pytest.mark.parametrize("case", list(CASES))
def test_no_import_once_the_devices_stream(tmp_path, hydra_dirs, case):
    module, overrides = CASES[case]
    if "estimator" in case:
        overrides = [*overrides, f"estimator={_artifact(tmp_path / 'T-s5.pt')}"]
    args = ["hardware=sim", *overrides, "progress=false", f"data_root={tmp_path / 'data'}", *hydra_dirs]
    env = {**os.environ, "PYTHONPATH": str(REPO), "HYDRA_FULL_ERROR": "0"}
    r = subprocess.run([sys.executable, "-c", PROBE, module, *args], cwd=tmp_path, env=env, capture_output=True,
                       text=True, timeout=240)
    assert r.returncode == 0, r.stderr[-3000:]
    (line,) = [ln for ln in r.stdout.splitlines() if ln.startswith("PROBE")]
    n_connected, late = line.split(" ", 2)[1:]
    assert int(n_connected) == 1, "the probe never saw the rig connect"
    assert late == "[]", f"modules imported during acquisition: {late}"
