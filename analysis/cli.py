"""`lsx-report`: the report's console script (`python -m analysis.report` under another name)."""

from __future__ import annotations

import sys


def report() -> None:
    """Answer --help, refuse a bad command line as a whole, then let Hydra run the report."""
    import analysis.config  # noqa: F401 - the report's schemas, for --help without the analysis stack
    from layerskin_exp.cli import answer_help, preflight

    answer_help("report", sys.argv[1:])
    from analysis import report as r

    r._check_command_line(sys.argv[1:])
    preflight("report", sys.argv[1:])
    r.main()
