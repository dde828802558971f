"""Waiting helpers shared by the driver-against-emulator tests (no timing claims: bounded polls)."""

from __future__ import annotations

import time


def wait_for(pred, timeout_s: float = 3.0) -> bool:
    """Poll pred() until it is true (True) or timeout_s passes (False)."""
    t0 = time.monotonic()
    while not pred():
        if time.monotonic() - t0 > timeout_s:
            return False
        time.sleep(0.003)
    return True


def healthy(drv) -> bool:
    """No fault, allowing a stall on a loaded machine to clear with the next fresh reply
    (a latched error, alarm or lost link never clears)."""
    return wait_for(lambda: drv.fault(time.monotonic_ns()) is None, 0.5)
