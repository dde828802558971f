"""Simulated twins of every device, observing one simulated world (`layerskin_exp.sim.world`)."""

from hardware.sim.build import SimRig, build_sim_rig

__all__ = ["SimRig", "build_sim_rig"]
