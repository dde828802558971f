"""`python -m layerskin_exp COMMAND [args]`: the project's commands in one place.

    calibrate   force-calibration campaign      (lsx-calibrate, python -m protocols.force_calibration)
    grip        grip-depth trial / sweep        (lsx-grip,      python -m protocols.grip_depth)
    report      analysis report                 (lsx-report,    python -m analysis.report)
    log         inspect / recover session files (lsx-log,       python -m layerskin_exp.log)
    live        a Foxglove live view of a run   (lsx-live,      python -m protocols.live)
    demo        the reduced demo campaign       (python -m layerskin_exp.demo)

Arguments after the command go to it unchanged (Hydra overrides, --help, -m, ...).

This dispatcher is the one place the core names the applications, by their entry points' names
(as [project.scripts] does), never importing one before it is asked for; the layering test
(tests/test_layering.py) allows it and nothing else.
"""

from __future__ import annotations

import sys

COMMANDS = {
    "calibrate": "protocols.force_calibration:cli",
    "grip": "protocols.grip_depth:cli",
    "report": "analysis.cli:report",
    "log": "layerskin_exp.commands:log",
    "live": "protocols.live:cli",
    "demo": "layerskin_exp.commands:demo",
}


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if not argv or argv[0] in ("-h", "--help", "help"):
        print(__doc__.strip())
        return 0
    if argv[0] not in COMMANDS:
        print(f"error: unknown command {argv[0]!r}; choose one of {', '.join(COMMANDS)}", file=sys.stderr)
        return 2
    module, func = COMMANDS[argv[0]].split(":")
    sys.argv = [f"{sys.argv[0]} {argv[0]}", *argv[1:]]
    import importlib

    result = getattr(importlib.import_module(module), func)()
    return result if isinstance(result, int) else 0


if __name__ == "__main__":
    sys.exit(main())
