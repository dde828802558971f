"""The simulated rig: a physically grounded two-layer skin, the platform and the manipulation world."""
