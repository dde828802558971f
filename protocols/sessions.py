"""`python -m protocols.sessions [DATA_ROOT]`: which design folder holds which sessions.

Sessions are laid out as `<data_root>/<protocol>/<design>/<trial>.mcap` (protocols/identity.py).
This lists, per protocol, each design folder with its count of complete trials (final `.mcap`
names), the `.partial` ones a live run is writing (in progress: its writer holds the file's lock,
layerskin_exp.log.container.lock) and the other `.partial` ones (interrupted), and the settings that tell the designs apart, read from
each folder's `design.yaml`. Nothing is opened but those manifests.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from layerskin_exp.log.container.lock import held
from protocols.identity import MANIFEST

PARTIAL_GLOB = "*.mcap.partial"


@dataclass
class Design:
    folder: Path
    settings: dict = field(default_factory=dict)  # dotted key -> value, from design.yaml
    complete: int = 0
    partial: int = 0  # .partial files no live writer holds: interrupted runs
    in_progress: int = 0  # .partial files a live writer holds


def _flatten(node, prefix: str = "") -> dict:
    if isinstance(node, dict):
        out = {}
        for k, v in node.items():
            out.update(_flatten(v, f"{prefix}{k}."))
        return out
    return {prefix[:-1]: node}


def scan_designs(protocol_root: Path) -> list[Design]:
    """The design folders under <data_root>/<protocol>/, in name order."""
    designs = []
    for folder in sorted(p for p in Path(protocol_root).iterdir() if p.is_dir()):
        manifest = folder / MANIFEST
        try:
            settings = _flatten(yaml.safe_load(manifest.read_text()) or {}) if manifest.is_file() else {}
        except (OSError, yaml.YAMLError):
            settings = {}
        writing = [held(p) for p in folder.glob(PARTIAL_GLOB)]
        designs.append(Design(folder, settings, len(list(folder.glob("*.mcap"))), writing.count(False),
                              writing.count(True)))
    return designs


def differing(designs: list[Design]) -> list[str]:
    """The dotted keys whose value is not the same in every design."""
    keys = sorted(set().union(*(d.settings for d in designs))) if designs else []
    return [k for k in keys if len({repr(d.settings.get(k, "<absent>")) for d in designs}) > 1]


def describe(data_root: Path) -> str:
    roots = [p for p in sorted(Path(data_root).iterdir()) if p.is_dir()] if Path(data_root).is_dir() else []
    lines = []
    for root in roots:
        designs = [d for d in scan_designs(root) if d.settings or d.complete or d.partial or d.in_progress]
        if not designs:
            continue
        keys = differing(designs)
        lines.append(f"{root}: {len(designs)} design(s)" + (f", differing in {', '.join(keys)}" if keys else ""))
        for d in designs:
            what = ", ".join(f"{k}={d.settings.get(k, '<absent>')}" for k in keys)
            lines.append(f"  {d.folder.name}  {d.complete} complete, "
                         + (f"{d.in_progress} in progress, " if d.in_progress else "") + f"{d.partial} interrupted"
                         + (f"  {what}" if what else "") + ("" if d.settings else f"  (no {MANIFEST})"))
    return "\n".join(lines) if lines else f"no session folders under {data_root}"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m protocols.sessions", description=__doc__.splitlines()[0])
    parser.add_argument("data_root", nargs="?", default="data", help="the protocols' data_root (default: data)")
    args = parser.parse_args(argv)
    if not Path(args.data_root).is_dir():
        print(f"error: data_root={args.data_root!r} is not a folder", file=sys.stderr)
        return 2
    print(describe(Path(args.data_root)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
