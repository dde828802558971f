"""hardware.priority: a real-time rig's process runs at `hardware.nice` (every thread, and what
it starts), is put back when the rig disconnects, and says clearly when the OS refuses; its heap
is held out of the cycle collector's scans for the trial."""

import gc
import logging
import os
import subprocess
import sys
import textwrap

import pytest

from hardware import build_rig
from hardware.priority import _threads, hold_heap, raise_priority
from layerskin_exp.config import ConfigError, validate
from tests.protocols.conftest import REPO


def _may_raise() -> bool:
    """Whether this machine lets a process raise its priority (root in a container may not: the
    capability decides), tried in a child so this interpreter is never touched."""
    r = subprocess.run([sys.executable, "-c", "import os; os.setpriority(os.PRIO_PROCESS, 0, os.nice(0) - 1)"],
                       capture_output=True, timeout=30)
    return r.returncode == 0


# Lowering niceness (raising priority) needs privilege; raising it never does.
PRIVILEGED = _may_raise()


def _run(code: str) -> str:
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    r = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True, env=env,
                       timeout=60)
    assert r.returncode == 0, r.stderr
    return r.stdout.strip()


def test_every_thread_and_what_it_starts_takes_the_niceness():
    # in a child, so this interpreter's own priority is never touched; +7 needs no privilege
    out = _run("""
        import os, threading, subprocess, sys
        from hardware.priority import raise_priority, _threads
        stop = threading.Event()
        old = threading.Thread(target=stop.wait); old.start()          # a thread from before
        restore = raise_priority(7)
        new = threading.Thread(target=stop.wait); new.start()          # and one started after
        nices = {os.getpriority(os.PRIO_PROCESS, t) for t in _threads()}
        child = subprocess.run([sys.executable, "-c", "import os; print(os.nice(0))"],
                               capture_output=True, text=True).stdout.strip()
        print(sorted(nices), child, restore is not None, len(_threads()) >= 3)
        stop.set(); old.join(); new.join()
    """)
    assert out == "[7] 7 True True"


def test_nothing_changes_for_null_or_the_niceness_in_effect():
    assert raise_priority(None) is None
    assert raise_priority(os.getpriority(os.PRIO_PROCESS, 0)) is None


def test_a_refused_raise_is_a_warning_naming_the_key_and_changes_nothing(monkeypatch, caplog):
    before = {t: os.getpriority(os.PRIO_PROCESS, t) for t in _threads()}

    def refuse(*args):
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(os, "setpriority", refuse)
    with caplog.at_level(logging.WARNING, logger="hardware.priority"):
        assert raise_priority(-10) is None
    assert "hardware.nice=-10" in caplog.text and "limits.conf" in caplog.text
    monkeypatch.undo()
    assert {t: os.getpriority(os.PRIO_PROCESS, t) for t in _threads()} == before


@pytest.mark.skipif(not PRIVILEGED, reason="raising priority needs root, CAP_SYS_NICE or an RLIMIT_NICE allowance")
def test_a_lab_rig_runs_raised_until_it_disconnects(make_cfg):
    cfg = make_cfg("lab")
    cfg.hardware.nice = -5
    before = os.getpriority(os.PRIO_PROCESS, 0)
    rig = build_rig(cfg, "platform")
    assert {os.getpriority(os.PRIO_PROCESS, t) for t in _threads()} == {-5}
    rig.disconnect()
    assert {os.getpriority(os.PRIO_PROCESS, t) for t in _threads()} == {before}


def test_a_rig_holds_its_heap_out_of_the_collector_until_it_disconnects(make_cfg, monkeypatch):
    """Everything the process holds when the rig is built is frozen (gc.freeze), so a full
    collection during the trial scans only what the trial makes (about 155 ms of held interpreter
    lock otherwise, in a process that has imported the framework); disconnecting hands it back."""
    assert gc.get_freeze_count() == 0
    cfg = make_cfg("lab")
    cfg.hardware.nice = None
    rig = build_rig(cfg, "platform")
    try:
        assert gc.get_freeze_count() > 10_000  # the interpreter's own modules at least
        # a freeze in effect is its owner's to undo: no second collection or freeze. Judged by
        # the calls, not the count, which falls whenever the rig's threads free a frozen object
        calls = []
        monkeypatch.setattr(gc, "collect", lambda *a: calls.append("collect"))
        monkeypatch.setattr(gc, "freeze", lambda: calls.append("freeze"))
        assert hold_heap() is None
        assert calls == []
        monkeypatch.undo()
    finally:
        rig.disconnect()
    assert gc.get_freeze_count() == 0


@pytest.mark.parametrize("bad", [-21, 20])
def test_a_niceness_out_of_range_names_the_key(make_cfg, bad):
    cfg = make_cfg("loopback")
    cfg.hardware.nice = None
    validate(cfg, "hardware")  # null: leave the priority as started
    cfg.hardware.nice = bad
    with pytest.raises(ConfigError, match=f"hardware.nice={bad}"):
        validate(cfg, "hardware")
