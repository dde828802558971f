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
- the simulator (backend "sim": host time is virtual): the simulated rig dates each trial
  itself (hardware.sim.build.SimRig.log_time), at the run's start (sim.rig.start_time, else the
  wall clock when the run started) plus the trial's slot in its campaign, so the trials of a
  campaign, resumed or not, follow each other, and a fixed start_time gives byte-identical files.
  A simulated session written without the rig (no offset given) is dated at the wall clock
  when it is opened.
"""

from __future__ import annotations

import time


def wall_offset_ns() -> int:
    """Unix ns minus monotonic ns, now (the offset of a session on time.monotonic_ns())."""
    return time.time_ns() - time.monotonic_ns()


def session_offset_ns(metadata: dict) -> tuple[int, str]:
    """(offset_ns, how it was chosen) for a session with this metadata, when the writer is given
    none (see the module doc)."""
    if metadata.get("backend") == "sim":
        return time.time_ns(), "simulated, written without the rig: host time 0 at the wall clock when opened"
    return wall_offset_ns(), "wall clock - monotonic clock at session start"
