"""Finite-element reference of the skin's stack (felupe), independent of the fast model.

`model` builds and solves a plane-strain section (see its docstring for what it includes and
misses); `python -m layerskin_exp.sim.fem_reference` regenerates the committed data in reference/,
which `layerskin_exp.sim.physics_checks` (`python -m layerskin_exp.sim.validate`) compares with the fast model."""
