"""Parameters of the simulated rig's devices (F/T, platform, arm, gripper, camera, clocks).

Placeholder created by the lead; owned and filled in by the rig engineer. `SimConfig` in
`layerskin_exp/sim/config.py` holds a `rig: RigConfig` field.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass
class RigConfig:
    pass
