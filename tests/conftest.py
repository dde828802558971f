import os
import tempfile

import pytest

os.environ.setdefault("MPLBACKEND", "Agg")

# Contact tables on disk (layerskin_exp.sim.table_cache): the protocol runs this suite starts as
# subprocesses share one folder of this session's own, never the user's cache; the in-process
# tests, which replace physics functions to show checks failing, use no disk cache at all.
_TABLES = tempfile.TemporaryDirectory(prefix="lsx-test-tables-")
os.environ["LAYERSKIN_CACHE_DIR"] = _TABLES.name


@pytest.fixture(autouse=True)
def _no_disk_tables_in_process(monkeypatch):
    from layerskin_exp.sim import table_cache

    monkeypatch.setattr(table_cache, "ENABLED", False)


@pytest.fixture(autouse=True)
def _priority_as_started():
    """A rig built in this process raises its priority and holds its heap until it disconnects
    (hardware.priority); one built and dropped by a test must not leave the rest of the suite so."""
    import gc

    from hardware.priority import set_niceness

    before = os.getpriority(os.PRIO_PROCESS, 0)
    frozen = gc.get_freeze_count()
    yield
    if os.getpriority(os.PRIO_PROCESS, 0) != before:
        set_niceness(before)
    if gc.get_freeze_count() and not frozen:  # its held heap, too (hardware.priority.hold_heap)
        gc.unfreeze()


@pytest.fixture
def hydra_dirs(tmp_path):
    """Overrides that keep Hydra's run/sweep folders inside tmp_path."""
    return [f"hydra.run.dir={tmp_path}/out", f"hydra.sweep.dir={tmp_path}/multirun"]
