"""Where a session's host timeline sits on the Unix epoch.

Every message keeps its host receive time on the host's monotonic clock (what the clock maps
and the reader's aligned arrays use) and its device time. MCAP log_time and the `timestamp` of
each Foxglove message are that host time moved onto the Unix epoch by one constant per session:

    unix_ns = host_t_ns + offset_ns

A constant, not a wall-clock reading per message, so log times stay exactly as monotonic as the
host clock (a wall-clock step from NTP never reorders a file) and host_t_ns = log_time - offset_ns
exactly. The offset is stored in the file's "log_time" metadata record.

Which offset:
- hardware clocks (lab, loopback: host times are time.monotonic_ns()): wall clock minus
  monotonic clock when the session starts, so a trial is dated when it ran;
- the simulator (backend "sim": host time is virtual, each run starting at sim.rig.host_start_s):
  SIM_EPOCH_NS plus one whole day per run, the day (0 .. SIM_DAYS-1, i.e. 2000 .. 2099) drawn
  from a hash of the resolved config (seed included). All trials of one run share the offset, so
  they follow each other as the virtual clock runs on; separate runs (sweep jobs, calibration
  and grip) land on separate days unless their config hashes collide (1 in 36,524 per pair).
  Deterministic: the same config gives byte-identical files, as the simulator does otherwise.
  A resumed campaign restarts the virtual clock, so its new trials can overlap earlier ones of
  the same run on that day.
"""

from __future__ import annotations

import hashlib
import json
import time

SIM_EPOCH_NS = 946_684_800 * 1_000_000_000  # 2000-01-01T00:00:00Z
SIM_DAYS = 36_524  # 2000-01-01 .. 2099-12-31
DAY_NS = 86_400 * 1_000_000_000


def wall_offset_ns() -> int:
    """Unix ns minus monotonic ns, now (the offset of a session on time.monotonic_ns())."""
    return time.time_ns() - time.monotonic_ns()


def simulated_offset_ns(config: dict | None) -> int:
    """The simulator's offset: SIM_EPOCH_NS plus the run's day, from a hash of its config."""
    text = json.dumps(config or {}, sort_keys=True, default=str).encode()
    day = int.from_bytes(hashlib.sha256(text).digest()[:8], "big") % SIM_DAYS
    return SIM_EPOCH_NS + day * DAY_NS


def session_offset_ns(metadata: dict) -> tuple[int, str]:
    """(offset_ns, how it was chosen) for a session with this metadata (see the module doc)."""
    if metadata.get("backend") == "sim":
        return simulated_offset_ns(metadata.get("config")), "simulated: 2000-01-01 + a day per config"
    return wall_offset_ns(), "wall clock - monotonic clock at session start"
