"""Console-script entry points of the core's own commands (the log tools, the demo); each
application keeps its own (`protocols.<app>:cli`, `analysis.cli:report`). See pyproject's
[project.scripts]."""

from __future__ import annotations


def log() -> int:
    """lsx-log: `python -m layerskin_exp.log` (inspect, recover, layout, export, view)."""
    from layerskin_exp.log.cli import main

    return main()


def demo() -> None:
    from layerskin_exp import demo as d

    d.main()
