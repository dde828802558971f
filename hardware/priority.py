"""The bench's scheduling priority: a real-time rig's process (its drivers' receive and poll
threads, the watchdog, the protocol loop, and on `loopback` the emulators it starts) runs at a
raised priority where the OS allows it, as robot control software does (ur_rtde's `rt_priority`,
ros2_control's real-time thread), so that an analysis job beside it cannot delay the stop path.

This is CFS niceness, not a real-time policy: every thread still yields to the kernel's own
workers, and a spinning bench cannot lock the machine up. Raising priority needs privilege:
root, CAP_SYS_NICE, or an RLIMIT_NICE allowance (`nice` in /etc/security/limits.conf, e.g.
`@robotics - nice -10`). Without it the bench runs at normal priority and says so once; its
watchdogs still judge the devices, not the scheduler (hardware.watchdog), but a genuine stall is
then caught later on a heavily loaded host.

The same stop path waits for Python's cycle collector: a full collection holds the interpreter
lock while it scans every tracked object, about 155 ms in a process that has imported the
framework (torch, numba, hydra, the simulator, the drivers), longer on a busy host, and a trial
that allocates can set one off at any moment. `hold_heap` therefore moves what the process holds
when the rig starts into the collector's permanent generation (gc.freeze, as long-running servers
do after start-up), so a collection during the trial scans only what the trial itself made; the
rig hands it back when it disconnects.
"""

from __future__ import annotations

import gc
import logging
import os
import sys
from collections.abc import Callable

log = logging.getLogger(__name__)

NICE_RANGE = (-20, 19)


def _threads() -> list[int]:
    """The ids whose niceness makes up this process's priority: every thread on Linux (where
    niceness is per thread, and a new thread or child process takes its creator's), else the
    process itself."""
    if sys.platform.startswith("linux"):
        try:
            return [int(t) for t in os.listdir("/proc/self/task")]
        except OSError:
            pass
    return [0]


def set_niceness(nice: int) -> None:
    """Every thread of this process to niceness `nice` (threads that end meanwhile are skipped).
    Raises PermissionError where the OS refuses (raising priority needs privilege)."""
    for tid in _threads():
        try:
            os.setpriority(os.PRIO_PROCESS, tid, nice)
        except ProcessLookupError:
            continue


def raise_priority(nice: int | None, key: str = "hardware.nice") -> Callable[[], None] | None:
    """Set every thread of this process to niceness `nice` (None: leave it). Returns a function
    that puts back the niceness the process had (call it when the rig disconnects), or None
    where nothing was changed: `nice` is None, already in effect, or not permitted (logged as a
    warning naming `key` and what to do)."""
    if nice is None:
        return None
    before = os.getpriority(os.PRIO_PROCESS, 0)
    if before == nice:
        return None
    try:
        set_niceness(nice)
    except PermissionError:
        try:
            set_niceness(before)  # the threads raised before the refusal
        except OSError:
            pass
        log.warning("%s=%d: not permitted to raise this process's priority (needs root, CAP_SYS_NICE or an "
                    "RLIMIT_NICE allowance, e.g. '@robotics - nice %d' in /etc/security/limits.conf); the bench "
                    "runs at normal priority. Set %s=null to silence this.", key, nice, nice, key)
        return None
    log.info("%s=%d: bench threads raised from niceness %d", key, nice, before)
    # threads made since took `nice` from their creator: they go back with the rest
    return lambda: set_niceness(before)


def hold_heap() -> Callable[[], None] | None:
    """Collect once, then freeze every object this process holds (gc.freeze): a full collection
    during the trial no longer scans them. Returns the function that hands them back to the
    collector (gc.unfreeze; call it when the rig disconnects), or None where a freeze is already
    in effect (whoever made it undoes it)."""
    if gc.get_freeze_count():
        return None
    gc.collect()
    gc.freeze()
    log.debug("bench heap held: %d objects outside the collector's scans", gc.get_freeze_count())
    return gc.unfreeze
