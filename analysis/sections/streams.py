"""Stream health of the sessions the report used: what the devices' drivers counted over each
trial (received, lost, dropped, duplicate, out of order, corrupt, reconnects), summed per device."""

from __future__ import annotations

from analysis.report_run import ReportRun


def stream_health(run: ReportRun) -> None:
    """results["stream_health"]: the sessions counted, those without the record (written before
    it was stored), the counters summed per device, and the sessions whose skin lost frames
    (each within the max_lost_skin_frames its run allowed, or it would not be complete)."""
    trials = [*run.camp.calibration, *run.camp.grip]
    totals: dict[str, dict[str, int]] = {}
    not_recorded, lossy = 0, 0
    for t in trials:
        if t.stream_health is None:
            not_recorded += 1
            continue
        for device, counters in t.stream_health.items():
            total = totals.setdefault(device, {})
            for k, v in counters.items():
                total[k] = total.get(k, 0) + int(v)
        skin = t.stream_health.get("skin", {})
        lossy += skin.get("lost", 0) + skin.get("dropped", 0) > 0
    run.results["stream_health"] = {"sessions": len(trials), "not_recorded": not_recorded,
                                    "sessions_with_lost_skin_frames": lossy,
                                    "devices": dict(sorted(totals.items()))}
