"""What produced a session or a report: software version, git commit and dirty flag, the
command-line overrides (Hydra's), the interpreter. Stored with every session's metadata (record
"provenance"); the resolved config goes beside it (record "config").

The commit is read from the checkout the package runs from; an installed wheel has none, and
says so (git_commit None) rather than naming whatever repository the working directory is in.
"""

from __future__ import annotations

import platform
import subprocess
import sys
from pathlib import Path

import layerskin_exp

_SOURCE = Path(layerskin_exp.__file__).resolve().parent.parent


def git_state(root: Path = _SOURCE) -> dict:
    """{"git_commit": sha or None, "git_dirty": bool or None} of the checkout at `root`.

    Dirty = tracked files differ from the commit (untracked files are not counted: data and
    outputs often live in the checkout)."""
    if not (root / ".git").exists():
        return {"git_commit": None, "git_dirty": None}
    try:
        sha = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True,
                             timeout=10, check=True).stdout.strip()
        status = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
                                capture_output=True, text=True, timeout=30, check=True).stdout
    except (OSError, subprocess.SubprocessError):
        return {"git_commit": None, "git_dirty": None}
    return {"git_commit": sha or None, "git_dirty": bool(status.strip())}


def hydra_overrides() -> list[str] | None:
    """The overrides of the running Hydra job (task overrides, as typed), or None outside Hydra."""
    try:
        from hydra.core.hydra_config import HydraConfig

        if not HydraConfig.initialized():
            return None
        return list(HydraConfig.get().overrides.task)
    except Exception:  # noqa: BLE001 - provenance must never stop a run
        return None


def provenance(overrides: list[str] | None = None) -> dict:
    """Everything above as one JSON-able dict; overrides default to the running Hydra job's."""
    return {
        "package": "layerskin-exp",
        "version": layerskin_exp.__version__,
        **git_state(),
        "overrides": overrides if overrides is not None else hydra_overrides(),
        "argv": list(sys.argv),
        "python": platform.python_version(),
    }
