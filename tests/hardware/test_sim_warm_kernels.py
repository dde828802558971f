"""Every kernel a trial calls is loaded (or compiled) when the simulated rig is built, not in the
trial: a compile inside a realtime trial holds the world's lock and stalls the streams."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

# In a fresh process (kernels already loaded by other tests would hide one the rig leaves out):
# which kernels gain a specialization between the rig being built and the end of a first move.
SCRIPT = r"""
import json, sys
import numpy as np
from numba.core.registry import CPUDispatcher
from hardware import build_rig
from layerskin_exp.sim import clocks, frame_kernels, ft_sensor, mechanics
from tests.hardware.conftest import app_config

def loaded():
    return {f"{m.__name__}.{k}": len(v.signatures) for m in (clocks, frame_kernels, ft_sensor, mechanics)
            for k, v in vars(m).items() if isinstance(v, CPUDispatcher)}

setup = sys.argv[1]
rig = build_rig(app_config("sim", 0), setup)
before = loaded()
rig.connect()
rig.begin_trial({"t": 0}, 0.0)
if setup == "platform":
    rig.platform.move_to(np.asarray(rig.platform.position_mm()) + [1.0, 0.0, -0.5], 2.0)
else:
    rig.gripper.move(40.0, 20.0, 50.0)
    rig.arm.move_linear(rig.arm.tcp_pose6() + [0.002, 0, 0, 0, 0, 0], 0.01, 0.1)
rig.clock.sleep(0.2)
for d in rig.devices():
    d.read_available()
after = loaded()
print(json.dumps(sorted(k for k in after if after[k] > before[k])))
"""


@pytest.mark.parametrize("setup", ["platform", "gripper"])
def test_no_kernel_loads_inside_the_first_trial(setup):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    out = subprocess.run([sys.executable, "-c", SCRIPT, setup], cwd=ROOT, env=env, capture_output=True,
                         text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    assert json.loads(out.stdout.strip().splitlines()[-1]) == []
