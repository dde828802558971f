import os
import tempfile
from pathlib import Path

import pytest

os.environ.setdefault("MPLBACKEND", "Agg")

# An xdist worker shares the cores with the other: one OpenBLAS thread each (and in the processes
# its tests start). Measured: a finite-element test took 75 s in each of two processes at once with
# OpenBLAS's default two threads, 12 s with one.
if os.environ.get("PYTEST_XDIST_WORKER"):
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    from threadpoolctl import threadpool_limits

    threadpool_limits(int(os.environ["OPENBLAS_NUM_THREADS"]), user_api="blas")

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


# Tests that run on the wall clock (a RealtimeWorld, the loopback emulators, a CPU load beside a
# trial, a protocol process signalled or killed mid-trial) share one xdist group: `--dist loadgroup`
# (make test) runs them one after another in one worker, so they never starve each other or race
# for the UR5e emulator's fixed ports (hardware.loopback.free_ur_host probes an address, then
# another process binds it). A test joins the group by its file (REALTIME_FILES), by the
# realtime_world fixture, by its module starting a RealtimeWorld or a CpuLoad itself, or by its own
# @pytest.mark.xdist_group("realtime").
REALTIME = "realtime"
REALTIME_FILES = (
    "hardware/test_loopback.py",  # whole protocols on hardware=loopback
    "hardware/test_loopback_under_load.py",  # the same beside tests/load.py's CpuLoad
    "hardware/test_emulate.py",  # standalone emulators on the devices' fixed ports
    "hardware/test_realtime.py",  # the world's pace against the wall clock
    "hardware/ur5e/test_ur5e_loopback.py",  # the UR5e emulator's fixed ports on chosen 127.0.0.N hosts
    "hardware/ur5e/test_ur5e_clients.py",
)


def _is_realtime(item) -> bool:
    rel = item.path.relative_to(Path(__file__).parent).as_posix()
    if rel in REALTIME_FILES:
        return True
    if "realtime_world" in getattr(item, "fixturenames", ()):
        return True
    module = getattr(item, "module", None)
    return any(hasattr(module, name) for name in ("start_realtime_world", "CpuLoad"))


def _module_fixture_file(item) -> str | None:
    """The test's file if the test uses a module-scoped fixture defined there (a solve, a simulated
    campaign built once and only read): its tests then share a group, so that the fixture is built
    once, in one worker, rather than once in each."""
    info = getattr(item, "_fixtureinfo", None)
    path = item.nodeid.split("::", 1)[0]
    for defs in (info.name2fixturedefs.values() if info else ()):
        if any(d.scope == "module" and d.baseid == path for d in defs):
            return path
    return None


@pytest.hookimpl(tryfirst=True)  # before xdist's own, which names each item's group in its node id
def pytest_collection_modifyitems(config, items):
    """Groups for `--dist loadgroup`; the grouped tests first (the real-time group, then each file
    with its module fixtures), so the long units start early and the single tests fill in behind."""
    rank = {}
    for item in items:
        marked = item.get_closest_marker("xdist_group")
        if marked is None and _is_realtime(item):
            item.add_marker(pytest.mark.xdist_group(REALTIME))
            marked = True
        elif marked is None and (path := _module_fixture_file(item)):
            item.add_marker(pytest.mark.xdist_group(path.replace("/", ".")))
            rank[item] = 1
            continue
        rank[item] = 0 if marked else 2
    items.sort(key=rank.__getitem__)  # stable: each file's tests keep their order


def pytest_configure(config):
    """`--dist loadgroup` under pytest 9.2 with pytest-xdist 3.8 or older spreads the real-time group
    over the workers without a word (pytest-xdist issue 1386): refuse it, saying why."""
    if getattr(config.option, "dist", "no") != "loadgroup":
        return
    from importlib.metadata import version

    xdist = tuple(int(p) for p in version("pytest-xdist").split(".")[:2] if p.isdigit())
    if pytest.version_tuple[:2] >= (9, 2) and xdist <= (3, 8):
        raise pytest.UsageError(f"--dist loadgroup does not group with pytest {pytest.__version__} and "
                                f"pytest-xdist {version('pytest-xdist')} (pytest-xdist issue 1386); "
                                "install the dev extra's pytest: pip install -e '.[dev]'")


@pytest.hookimpl(trylast=True)
def pytest_collection_finish(session):
    """A worker of `--dist loadgroup` whose grouped tests kept their plain ids would spread the group
    over the workers without a word (pytest-xdist issue 1386, pytest 9.2): refuse the run instead."""
    if not getattr(session.config.option, "loadgroup", False):
        return
    lost = [i.nodeid for i in session.items if i.get_closest_marker("xdist_group") and "@" not in
            i.nodeid.rsplit("]", 1)[-1]]
    if lost:
        raise pytest.UsageError(f"--dist loadgroup: {len(lost)} grouped tests have no group in their id "
                                f"({lost[0]}); this pytest and pytest-xdist do not group (pyproject.toml)")
