"""Why a motion ended: the one vocabulary of stop reasons and guard trips.

A protocol logs the reason its motion ended as a "stop" event (the first one is the trial's
`stop_reason`); a guard on the rig trips with a string that starts with one of the trip names
below, followed by ": <what it saw>". Only a *safety trip* is a safety event: it is logged at
warning level and the trial's outcome records it. The other trips are per-sample stop
conditions (a press stopping on the sample that reaches its target, the slow zone near the
force limit) and are logged at info level like any normal stop.
"""

from __future__ import annotations

# Normal ends of a motion (event kind "stop").
TARGET_REACHED = "target_reached"  # press at its target force, grip trajectory done
SHEAR_REACHED = "shear_reached"  # slide at slide.shear_stop_n
SKIN_EDGE = "skin_edge"  # slide reached the edge of the sensing area
DEPTH_LIMIT = "depth_limit"  # press reached the workspace floor before its target
NO_CONTACT = "no_contact"  # the grip approach closed fully without contact
LOADING = "loading"  # a press past press.slow_above_n: it goes on at press.load_speed_mm_s

# Guard trips (Rig.tripped starts with one of these).
FORCE_LIMIT = "force_limit"  # F/T normal force over safety.max_normal_force_n
SKIN_LOAD_LIMIT = "skin_load_limit"  # grip rig: both layers over safety.max_skin_load_fraction
SLOW_ZONE = "slow_zone"  # near the force limit: stop, go on at safety.slow_zone_speed_mm_s
SAFETY_TRIPS = (FORCE_LIMIT, SKIN_LOAD_LIMIT)


def trip_name(tripped: str) -> str:
    """The trip's name, from a guard's "<name>: <detail>" string."""
    return tripped.split(":", 1)[0].strip()


def is_safety_trip(tripped: str | None) -> bool:
    """True for a trip of a safety limit (as opposed to a per-sample stop condition)."""
    return tripped is not None and trip_name(tripped) in SAFETY_TRIPS
