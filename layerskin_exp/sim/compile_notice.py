"""Say so when the simulator's numba kernels compile (a fresh install's first run only).

Numba compiles a kernel on its first call and caches it on disk; a later process loads it in
milliseconds. On a fresh install that first compile takes a minute or two, and without a word
a newcomer sees a run that hangs. numba reports each compilation as a "numba:compile" event
(a cache hit is not one), so one process-wide listener can announce the first and time them all.
"""

from __future__ import annotations

import atexit
import logging
import sys
import threading
import time

from numba.core import event

log = logging.getLogger(__name__)


class _CompileNotice(event.Listener):
    """Times top-level compilations (a kernel's callees compile inside its own event)."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.depth = 0
        self.started = 0.0
        self.pending_s = 0.0  # compile time not yet reported
        self.pending_n = 0
        self.announced = False

    def on_start(self, ev) -> None:
        with self.lock:
            if self.depth == 0:
                self.started = time.perf_counter()
                if not self.announced:
                    self.announced = True
                    _say("compiling kernels, first run only (numba caches them on disk; later runs load "
                         "them in about a second)...")
            self.depth += 1

    def on_end(self, ev) -> None:
        with self.lock:
            self.depth -= 1
            if self.depth == 0:
                self.pending_s += time.perf_counter() - self.started
                self.pending_n += 1

    def report(self, *_args) -> None:
        """Log the compile time gathered since the last report (nothing if none)."""
        with self.lock:
            n, s = self.pending_n, self.pending_s
            self.pending_n, self.pending_s = 0, 0.0
        if n:
            _say(f"compiled {n} kernel{'' if n == 1 else 's'} in {s:.0f} s (first run only)")


def _say(msg: str) -> None:
    # A status line, not a problem: printed like a progress bar (Hydra's console shows warnings
    # only) and kept in the job log at INFO.
    print(msg, file=sys.stderr, flush=True)
    log.info(msg)


_NOTICE: _CompileNotice | None = None


def install() -> _CompileNotice:
    """Register the listener once per process; its report() runs at exit too. Returns it, so a
    caller can report at a natural boundary (the start of the next trial)."""
    global _NOTICE
    if _NOTICE is None:
        _NOTICE = _CompileNotice()
        event.register("numba:compile", _NOTICE)
        atexit.register(_NOTICE.report)
    return _NOTICE
