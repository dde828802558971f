"""`python -m protocols.live PROTOCOL [--hold] [overrides]`: run a protocol and watch it in Foxglove.

    python -m protocols.live grip_depth hardware=loopback grip_depth=9     # (lsx-live ...)
    python -m protocols.live force_calibration positions.count=2 live_port=8766
    python -m protocols.live grip_depth --hold                            # stays up after the run

The same as the protocol's own command with live=true: a Foxglove WebSocket server on
127.0.0.1:live_port serves both layer maps, their CoP, force, poses, the frame tree and the
events, thinned to display rate. Every client is sent, when it subscribes, what was served
before (every event, and the latest ten minutes or so of each other topic); --hold
(live_hold=true) keeps the server up after the run until Ctrl-C, so a client that connects then
is shown the whole run: maps, plots, poses and events.

In Foxglove: Open connection > Foxglove WebSocket > ws://127.0.0.1:8765, then Layouts > Import
the file `python -m layerskin_exp.log layout gripper` (or `platform`) writes. The server is the
Foxglove SDK's and speaks the subprotocol foxglove.sdk.v1 (and v1.1), which the current Foxglove
app offers; clients that offer only foxglove.websocket.v1 (older Foxglove Studio releases) are
refused by the SDK, reported once as a warning. The simulated rig (hardware=sim) runs much faster
than real time; hardware=loopback runs in real time.
"""

from __future__ import annotations

import sys

PROTOCOLS = {"force_calibration": "protocols.force_calibration", "grip_depth": "protocols.grip_depth",
             "calibrate": "protocols.force_calibration", "grip": "protocols.grip_depth"}


def cli(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if not argv or argv[0] in ("-h", "--help") or argv[0] not in PROTOCOLS:
        print(__doc__.strip(), file=sys.stderr if argv and argv[0] not in ("-h", "--help") else sys.stdout)
        return 0 if argv and argv[0] in ("-h", "--help") else 2
    import importlib

    module = importlib.import_module(PROTOCOLS[argv[0]])
    hold = ["live_hold=true"] if "--hold" in argv[1:] else []
    rest = [a for a in argv[1:] if not a.startswith("live=") and a != "--hold"]
    sys.argv = [f"{sys.argv[0]} {argv[0]}", "live=true", *hold, *rest]
    module.cli()
    return 0


if __name__ == "__main__":
    sys.exit(cli())
