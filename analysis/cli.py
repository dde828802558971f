"""`lsx-report`: the report's console script (`python -m analysis.report` under another name)."""

from __future__ import annotations

import importlib


def report() -> None:
    """Answer --help, refuse a bad command line as a whole, then let Hydra run the report."""
    import analysis.config  # noqa: F401 - the report's schemas, for --help without the analysis stack
    from layerskin_exp.cli import run_command

    def check(argv: list[str]) -> None:
        from analysis import report as r  # the analysis stack (torch): not for --help

        r._check_command_line(argv)

    run_command("report", lambda: importlib.import_module("analysis.report").main, before=[check])
