"""Contact tables kept on disk, so that each process of a sweep does not solve them again.

Solving one design's contact tables (`contact.build_tables`) takes about 2 s for the hemisphere
and 12 s for the rod on one core, reading them back 8 ms (benchmarks/contact_tables), and every
process that simulates the design needs them: a campaign, each job of a grip sweep under the
joblib or submitit launcher, each protocol run of the test suite. They are a pure function of the
design's parameters and of the simulator's code, so a file is stored under a key that hashes
both: the caller's description of the design (the config's repr) and the bytes of every module
of `layerskin_exp.sim` and of `layerskin_exp/rig.py` (the rig's facts they read), with numpy's
and scipy's versions. Editing the simulator therefore never reads a stale table.

Where: `$LAYERSKIN_CACHE_DIR` when set (set to an empty string: no disk cache), else
`$XDG_CACHE_HOME/layerskin-exp/contact-tables` (`~/.cache/...`). A file that cannot be read is
solved again and replaced; a folder that cannot be written only costs the time. Writes are
atomic (temp file, then rename), so parallel jobs never read half a file.

`ENABLED` switches the disk layer off for this process (the test suite does so for its
in-process tests, which replace physics functions to show checks failing and must neither read
nor write tables made with the real ones).
"""

from __future__ import annotations

import dataclasses
import hashlib
import logging
import os
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
import scipy

from layerskin_exp.sim.contact import ContactTables

log = logging.getLogger(__name__)

ENV = "LAYERSKIN_CACHE_DIR"
ENABLED = True
_CODE_HASH: str | None = None


def cache_dir() -> Path | None:
    """The folder tables are kept in, or None when the disk cache is off."""
    if not ENABLED:
        return None
    if ENV in os.environ:
        return Path(os.environ[ENV]) / "contact-tables" if os.environ[ENV] else None
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "layerskin-exp" / "contact-tables"


def code_hash() -> str:
    """sha256 over the simulator's modules and the numerical libraries' versions."""
    global _CODE_HASH
    if _CODE_HASH is None:
        h = hashlib.sha256(f"numpy {np.__version__} scipy {scipy.__version__}".encode())
        here = Path(__file__).parent
        # the simulator's modules, and the rig's facts they read (indenter and rod radii, pitch)
        for path in [*sorted(here.glob("*.py")), here.parent / "rig.py"]:
            h.update(path.name.encode())
            h.update(path.read_bytes())
        _CODE_HASH = h.hexdigest()
    return _CODE_HASH


def simulator_version() -> str:
    """Short form of code_hash: what simulated sessions record of the simulator that made them
    (protocols.identity puts it in the design, the demo in its data root)."""
    return code_hash()[:12]


def _file(folder: Path, design_key: str) -> tuple[Path, str]:
    full = f"{code_hash()}\n{design_key}"
    return folder / (hashlib.sha256(full.encode()).hexdigest()[:32] + ".npz"), full


def _load(path: Path, full_key: str) -> ContactTables | None:
    try:
        with np.load(path, allow_pickle=False) as z:
            if str(z["_key"]) != full_key:  # a hash collision, or a file from elsewhere
                return None
            return ContactTables(**{f.name: (str(z[f.name]) if f.name == "kind" else z[f.name])
                                    for f in dataclasses.fields(ContactTables)})
    except FileNotFoundError:
        return None
    except Exception as exc:  # noqa: BLE001 - a damaged or foreign file is solved again
        log.warning("contact-table cache %s unreadable (%s); solving again", path, exc)
        return None


def _store(path: Path, full_key: str, tables: ContactTables) -> None:
    arrays = {f.name: np.asarray(getattr(tables, f.name)) for f in dataclasses.fields(ContactTables)}
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.stem, suffix=".tmp")
        try:
            with os.fdopen(fd, "wb") as f:
                np.savez(f, _key=np.asarray(full_key), **arrays)
            os.replace(tmp, path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
    except OSError as exc:
        log.info("contact tables not kept on disk (%s): %s", path.parent, exc)


def load_or_build(design_key: str, build: Callable[[], ContactTables]) -> ContactTables:
    """The tables stored under `design_key` for this simulator code, or `build()`'s, stored."""
    folder = cache_dir()
    if folder is None:
        return build()
    path, full = _file(folder, design_key)
    tables = _load(path, full)
    if tables is None:
        tables = build()
        _store(path, full, tables)
    return tables
