"""Console-script entry points for commands whose modules are run with `python -m` (the
protocols define their own `cli()`); see pyproject's [project.scripts]."""

from __future__ import annotations

import sys


def report() -> None:
    """lsx-report: `python -m analysis.report` as a console script."""
    from analysis import report as r
    from layerskin_exp.cli import preflight

    r._check_command_line(sys.argv[1:])
    preflight("report", sys.argv[1:])
    r.main()


def log() -> int:
    """lsx-log: `python -m layerskin_exp.log` (inspect, recover, layout)."""
    from layerskin_exp.log.cli import main

    return main()


def demo() -> None:
    from layerskin_exp import demo as d

    d.main()
