"""`lsx-report`: the report's console script (`python -m analysis.report` under another name)."""

from __future__ import annotations

import sys


def report() -> None:
    """Refuse a bad command line as a whole, then let Hydra run the report."""
    from analysis import report as r
    from layerskin_exp.cli import preflight

    r._check_command_line(sys.argv[1:])
    preflight("report", sys.argv[1:])
    r.main()
