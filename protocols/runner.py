"""The shared trial runner: file naming, resume, logging, safe abort, per-trial summary.

A trial is one session file. It is written under a temporary name (`<name>.mcap.partial`) and
renamed atomically once closed complete, so a campaign stopped at any point leaves each trial
either complete under its final name or not there at all (an interrupted attempt stays as the
`.partial` file, readable and marked aborted, until the rerun overwrites it). Whether a trial is
complete is read back from the file itself.

Outcomes: "complete" (the trial ran as planned, no sample over a safety limit); "complete
(safety stop: <trip>; <n> samples over the limit)" (a safety limit stopped the motion, the
protocol retracted and finished the trial: its data are kept and analysed, and a rerun does not
repeat it; every sample over the limit is a "safety" event in the file); "incomplete: <n> skin
frames lost (...)" (the trial ran to its end, but its skin stream lost more frames than
`max_lost_skin_frames` allows: kept as `.partial`, run again by a rerun, the run goes on with
the next trial); "aborted: <reason>" (kept as `.partial`, run again by a rerun). Every trial's file stores what each device's driver counted
over the trial (received, lost, duplicate, out of order, corrupt, reconnects; `trial_health`).
A complete file is never replaced: a rerun skips it when its identity matches and refuses
(`TrialConflictError`) when the same path holds a trial of another identity, read from the parts
that survive when the file is damaged. A damaged file whose identity matches or cannot
be read is moved aside (`<name>.mcap.damaged`, reported) before the trial is recorded again. So
is a complete file whose stored skin losses exceed this run's `max_lost_skin_frames` (written
under a looser limit: `<name>.mcap.over-limit`): it is not complete by this run's measure.
"""

from __future__ import annotations

import dataclasses
import logging
import zlib
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

import numpy as np

from hardware.interfaces import DeviceError
from hardware.rig import Rig
from layerskin_exp.log import SessionFileError, SessionWriter, load_session
from layerskin_exp.log.view import FrameTree, SkinView
from layerskin_exp.types import (
    GripperState,
    MarkerDetection,
    ProtocolEvent,
    StagePosition,
    TwoLayerFrame,
    Wrench,
)
from protocols.stops import is_safety_trip

PARTIAL_SUFFIX = ".partial"
COMPLETE = "complete"
# Settings that add a view to a trial (camera images, live estimates) without changing its data:
# not part of its identity, so a rerun with them skips a complete trial (and says what it lacks).
VIEW_KEYS = ("save_images", "estimator")

log = logging.getLogger(__name__)


def trial_rng(seed: int, *keys: int | str) -> np.random.Generator:
    """A generator determined by the seed and the trial's labels only (not by run order)."""
    entropy = [seed & 0xFFFFFFFF] + [k & 0xFFFFFFFF if isinstance(k, int) else zlib.crc32(k.encode())
                                     for k in keys]
    return np.random.default_rng(np.random.SeedSequence(entropy))


# A trial is stopped at its timeout; the margin covers what follows (the last drain, the close).
SLOT_MARGIN_S = 10.0


def trial_slot_s(index: int, trial_timeout_s: float) -> float:
    """Where trial `index` of a campaign starts, s after the run's start, on a simulated clock
    (the simulated rig dates it there): slots of the timeout plus a margin never overlap, so the
    trials of a campaign follow each other in run order whichever of them a run does."""
    return index * (trial_timeout_s + SLOT_MARGIN_S)


class ProtocolError(RuntimeError):
    """The protocol could not carry out a trial as planned (e.g. no contact found)."""


class TrialConflictError(ProtocolError):
    """The trial's file holds a complete trial of another identity; it is left untouched."""


def outcome_after(safety_trip: str | None, health: dict | None = None, max_lost_skin_frames: int | None = None,
                  safety_samples: int = 1) -> str:
    """The outcome of a trial that ran to its end: plain complete only when no sample went over a
    safety limit, else complete with the first trip and how many samples were over
    ("complete (safety stop: <trip>; <n> samples over the limit)"); incomplete when the skin lost
    more frames than max_lost_skin_frames (None: no limit) by the trial's stream health
    (trial_health): sequence gaps plus frames a full driver buffer let go."""
    lost = lost_skin_frames(health)
    if over_the_limit(lost, max_lost_skin_frames):
        return f"incomplete: {lost} skin frames lost (limit max_lost_skin_frames={max_lost_skin_frames})"
    if safety_trip is None:
        return COMPLETE
    count = f"{safety_samples} sample{'' if safety_samples == 1 else 's'} over the limit"
    return f"{COMPLETE} (safety stop: {safety_trip}; {count})"


def lost_skin_frames(health: dict | None) -> int:
    """Skin frames a trial lost by its stream health: sequence gaps plus frames a full driver buffer
    let go (0 where the file stores no health: written before it was stored)."""
    skin = (health or {}).get("skin", {})
    return int(skin.get("lost", 0)) + int(skin.get("dropped", 0))


def over_the_limit(lost: int, max_lost_skin_frames: int | None) -> bool:
    return max_lost_skin_frames is not None and lost > max_lost_skin_frames


def device_health(rig: Rig) -> dict[str, dict[str, int]]:
    """Each device's stream-health counters as they stand now (drivers count from connect): the
    StreamHealth fields, and "dropped" where the driver counts frames its full buffer let go."""
    out = {}
    for d in rig.devices():
        counters = {k: int(v) for k, v in dataclasses.asdict(d.health).items()}
        dropped = getattr(d, "ring_dropped", None)
        if isinstance(dropped, int):
            counters["dropped"] = dropped
        out[d.name] = counters
    return out


def trial_health(before: dict[str, dict[str, int]], now: dict[str, dict[str, int]]) -> dict[str, dict[str, int]]:
    """What each device counted between two device_health readings (a counter that went back,
    a driver that started counting again, counts from zero)."""
    out = {}
    for device, counters in now.items():
        start = before.get(device, {})
        out[device] = {k: v - start.get(k, 0) if v >= start.get(k, 0) else v for k, v in counters.items()}
    return out


class Terminated(BaseException):
    """The run was asked to stop: SIGTERM (a process manager or SLURM ending the job) or Ctrl-C.
    str(exc) says which."""


_termination: list[str] = []
_raised: list[bool] = []  # Terminated was raised once: the run is closing its trial and exiting
_closing: list[bool] = []  # the run is winding down (ended, failed or stopped): its devices are closing


def request_termination(reason: str = "terminated (SIGTERM)") -> None:
    """Ask the running protocol to stop (safe from a signal handler: it only records the
    request). The control loop raises Terminated at its next tick (and run_trial before a trial
    starts), so the trial file is closed "aborted" at a safe point, never in the middle of a write;
    `terminate_now` is the last resort where no tick comes."""
    if not _termination:
        _raised.clear()
        _termination.append(reason)


def termination_pending() -> bool:
    return bool(_termination)


def termination_reason() -> str | None:
    """Why the run was asked to stop ("terminated (SIGTERM)", "interrupted (Ctrl-C)"), if it was."""
    return _termination[0] if _termination else None


def check_termination() -> None:
    if _termination:
        _raised.append(True)
        raise Terminated(_termination[0])


def terminate_now() -> None:
    """Raise Terminated here, wherever the run is (a signal handler's last resort when no tick
    acted on the request: a wait on a device, a long computation), unless it was raised already
    and the run is closing its trial, or the run is winding down anyway (`winding_down`): that
    cleanup is not cut short."""
    if _termination and not _raised and not _closing:
        check_termination()


def winding_down(yes: bool = True) -> None:
    """The run has ended, failed or been stopped and is closing its trial and devices: a signal
    from now on no longer raises into that (protocols.app; cleared when a run starts)."""
    _closing.clear()
    if yes:
        _closing.append(True)


@dataclass
class RunFiles:
    """The session files one protocol run wrote, for the line it ends with (protocols.app)."""

    folder: Path | None = None
    written: int = 0  # complete, under their final names
    interrupted: list[Path] = field(default_factory=list)  # closed aborted, kept as <name>.mcap.partial
    incomplete: list[str] = field(default_factory=list)  # "<name>: <outcome>" of trials closed incomplete
    already_complete: int = 0
    set_aside: list[Path] = field(default_factory=list)  # moved to <name>.mcap.damaged / .over-limit

    def reset(self) -> None:
        self.folder, self.written, self.interrupted, self.already_complete = None, 0, [], 0
        self.set_aside, self.incomplete = [], []

    def record(self, path: Path, how: str, outcome: str = "") -> None:
        """how: "written", "interrupted" (path: the .partial), "incomplete" (path: the .partial;
        outcome: why), "already_complete" or "set_aside" (path: where the file now is: damaged, or
        complete over this run's lost-frame limit)."""
        self.folder = path.parent
        if how == "incomplete":
            self.incomplete.append(f"{path.name.removesuffix('.mcap' + PARTIAL_SUFFIX)}: {outcome}")
        elif how == "set_aside":
            self.set_aside.append(path)
        elif how == "written":
            self.written += 1
        elif how == "interrupted":
            self.interrupted.append(path)
        else:
            self.already_complete += 1

    def stop_note(self) -> str:
        """What a run stopped early left of its trial in progress, for the line that says it stopped."""
        if self.interrupted:
            return f"the trial in progress is kept as {self.interrupted[-1].name} (aborted)"
        return "no trial was in progress" if self.folder is not None else "no trial had started, nothing was written"

    def line(self) -> str:
        if self.folder is None:
            return "no session file written"
        s = f"{self.written} session file{'' if self.written == 1 else 's'} written to {self.folder}"
        if self.interrupted:
            s += f", {len(self.interrupted)} interrupted (kept as .mcap.partial; a rerun runs it again)"
        if self.incomplete:
            s += (f", {len(self.incomplete)} incomplete (kept as .mcap.partial; a rerun runs it again): "
                  + "; ".join(self.incomplete))
        if self.already_complete:
            s += f"; {self.already_complete} already complete there"
        if self.set_aside:
            # each name says why: .damaged, or .over-limit (complete over this run's lost-frame limit)
            s += (f"; {len(self.set_aside)} file(s) moved aside, not replaced: "
                  + ", ".join(p.name for p in self.set_aside))
        return s


# What the current run wrote: reset by protocols.app when a run starts, filled by run_trial.
RUN_FILES = RunFiles()


def complete_session(path: Path):
    """The session at `path` when it is a readable, undamaged, complete trial, else None."""
    if not path.is_file():
        return None
    try:
        session = load_session(path, warn=False)
    except SessionFileError:
        return None
    return session if session.complete else None


def surviving_identity(path: Path) -> str | None:
    """The identity a damaged or incomplete file at `path` was recorded with, read from the parts
    that survive; None when no readable record holds it."""
    try:
        identity = load_session(path, warn=False).metadata.get("identity")
    except SessionFileError:
        return None
    return identity if isinstance(identity, str) else None


def trial_is_complete(path: Path, identity: str | None = None, max_lost_skin_frames: int | None = None) -> bool:
    """True when `path` is a readable, undamaged, complete session recorded with `identity` whose
    skin lost no more frames than `max_lost_skin_frames` (None: any number); raises
    TrialConflictError when it holds a trial of another identity (given one), complete or damaged."""
    session = complete_session(path)
    check_no_conflict(path, identity, session)
    return session is not None and not over_the_limit(lost_skin_frames(session.stream_health), max_lost_skin_frames)


def check_no_conflict(path: Path, identity: str | None, session=None) -> None:
    """Refuse (TrialConflictError) when `path` holds a trial of another identity: a complete one,
    or a damaged one whose identity survives. session: the complete session already read from
    `path`, if it was."""
    if identity is None or not path.is_file():
        return
    session = complete_session(path) if session is None else session
    recorded = session.metadata.get("identity") if session is not None else surviving_identity(path)
    if recorded is None or recorded == identity:
        return
    what = "a complete trial" if session is not None else "a damaged trial"
    raise TrialConflictError(
        f"{path} holds {what} recorded with another configuration (identity "
        f"{str(recorded)[:12]}..., this run {identity[:12]}...); it is not replaced. "
        "Record this one under another data_root, or move that file away first")


def set_aside(path: Path, why: str = "damaged") -> Path:
    """Move the file at `path` to a sibling `<name>.mcap.<why>[-k]` (never replacing one; out of
    the `*.mcap` a folder's sessions are listed by) so that the trial can be recorded again;
    returns the new path. why: "damaged", or "over-limit" (complete, but its skin lost more frames
    than this run allows)."""
    k = 0
    while True:
        aside = path.with_name(f"{path.name}.{why}{'' if k == 0 else f'-{k}'}")
        if not aside.exists():
            break
        k += 1
    path.rename(aside)
    return aside


@dataclass
class TrialResult:
    """What a trial did; `summary()` is the one line printed per trial."""

    name: str
    labels: dict
    path: str
    outcome: str
    duration_s: float = 0.0
    peak_fz_n: float | None = None
    peak_shear_n: float | None = None
    stop_reason: str | None = None
    skipped: bool = False
    extra: dict = field(default_factory=dict)

    def summary(self) -> str:
        if self.skipped:
            return f"{self.name}: already complete, skipped" + (f" ({self.extra['note']})" if "note" in self.extra
                                                                 else "")
        parts = [self.name, f"{self.duration_s:.2f} s"]
        if self.peak_fz_n is not None:
            parts.append(f"Fz max {self.peak_fz_n:.2f} N")
        if self.peak_shear_n is not None:
            parts.append(f"|Fxy| max {self.peak_shear_n:.2f} N")
        parts += [f"{k} {v}" for k, v in self.extra.items()]
        parts.append(f"stop {self.stop_reason or '-'}")
        parts.append(self.outcome)
        return " | ".join(parts)

    def as_dict(self) -> dict:
        return {"name": self.name, "labels": self.labels, "path": self.path, "outcome": self.outcome,
                "duration_s": self.duration_s, "peak_fz_n": self.peak_fz_n, "peak_shear_n": self.peak_shear_n,
                "stop_reason": self.stop_reason, "skipped": self.skipped}


class TrialLog:
    """An open session file bound to the rig: `drain()` moves everything acquired into the log.

    Keeps the latest samples and running peaks the protocols decide on. The file is written in
    log-time order (streaming readers, a live tail and `mcap cat` see time run forward): each
    drain writes what the devices handed over since the last one sorted by host receive time,
    then the frame tree at the drain's time. An event is written at the rig's time after a drain
    up to that time (what it drains is handed to the next drain's caller, so the control loop
    still sees every sample). derive: functions of the drained skin frames returning records
    written with them (the online estimates, see protocols.grip.log_estimates).
    """

    def __init__(self, writer: SessionWriter, rig: Rig, save_images: bool = False) -> None:
        self.writer = writer
        self.rig = rig
        self.save_images = save_images
        self.peak_fz_n: float | None = None
        self.peak_shear_n: float | None = None
        self.last_wrench: Wrench | None = None
        self.last_stage: StagePosition | None = None
        self.last_gripper: GripperState | None = None
        self.stop_reason: str | None = None
        self.safety_trip: str | None = None  # the first safety limit that tripped in this trial
        self.safety_samples = 0  # samples over a safety limit in this trial (each a "safety" event)
        self.derive: list[Callable[[list[TwoLayerFrame]], list]] = []
        self._drained_ns: int | None = None  # rig time of the last drain
        self._carried: tuple[list, list] = ([], [])  # drained for an event, not yet returned
        self._last_image_seq: int | None = None
        self._noted_trip: str | None = None
        # What Foxglove draws besides the raw streams: the frame tree's fixed part, CoP overlays.
        calibration = getattr(rig.camera, "calibration", None) if rig.camera is not None else None
        self.frames = FrameTree(writer, "gripper" if rig.arm is not None else "platform",
                                calibration() if calibration is not None else None)
        self.view = SkinView()

    def _event(self, kind: str, message: str, **detail) -> ProtocolEvent:
        """The event at the rig's time, logged to the job log (not yet to the file)."""
        t_ns = self.rig.clock.now_ns()
        log.log(logging.WARNING if kind in ("error", "safety") else logging.INFO, "%s: %s: %s %s",
                self.writer.path.name.removesuffix(".mcap" + PARTIAL_SUFFIX), kind, message, detail or "")
        return ProtocolEvent(kind=kind, message=message, host_t_ns=t_ns, device_t_ns=t_ns, detail=detail)

    def event(self, kind: str, message: str, **detail) -> None:
        if self.rig.clock.now_ns() != self._drained_ns:  # records received meanwhile are older than the event
            self._carried = self.drain()
        self.writer.write(self._event(kind, message, **detail))

    def stop(self, reason: str, **detail) -> str:
        """Log the reason the motion ended (kind "stop"); the first one is the trial's."""
        self.event("stop", reason, **detail)
        if self.stop_reason is None:
            self.stop_reason = reason
        return reason

    def drain(self) -> tuple[list[TwoLayerFrame], list[Wrench]]:
        """Write every sample acquired since the last call; returns the new skin frames and wrenches."""
        rig, w = self.rig, self.writer
        carried_frames, carried_wrenches = self._carried
        self._carried = ([], [])
        # (host receive time ns, write) of everything this drain writes; sorted before writing
        out: list[tuple[int, Callable[[], None]]] = []

        def put(records) -> None:
            out.extend((int(r.host_t_ns), partial(w.write, r)) for r in records)

        frames = rig.skin.read_available()
        put(frames)
        if frames:
            last = frames[-1]
            out.extend((int(last.host_t_ns), partial(w.write_view, topic, schema, payload, last.host_t_ns))
                       for topic, schema, payload in self.view.summary(last))
            for derive in self.derive:
                put(derive(frames))
        wrenches: list[Wrench] = []
        if rig.ft is not None:
            wrenches = rig.ft.read_available()
            put(wrenches)
            if wrenches:
                self.last_wrench = wrenches[-1]
                force_n = np.stack([s.force_n for s in wrenches])
                fz_max = float(force_n[:, 2].max())
                shear_max = float(np.hypot(force_n[:, 0], force_n[:, 1]).max())
                self.peak_fz_n = fz_max if self.peak_fz_n is None else max(self.peak_fz_n, fz_max)
                self.peak_shear_n = shear_max if self.peak_shear_n is None else max(self.peak_shear_n, shear_max)
        # Every sample over a safety limit is a safety event (warning), at the sample's time, whatever
        # else was latched then; a per-sample stop condition (a press on its target, the slow zone)
        # is a normal stop (info), noted once per trip.
        over = rig.take_ceiling_events()
        if over:
            self.safety_trip = self.safety_trip or over[0][0]
            self.safety_samples += len(over)
            log.warning("%s: safety: %s%s", self.writer.path.name.removesuffix(".mcap" + PARTIAL_SUFFIX),
                        over[0][0], f" (and {len(over) - 1} more samples over the limit)" if len(over) > 1 else "")
            floor_ns = self._drained_ns or 0  # a sample read late is written after what is written already
            put([ProtocolEvent(kind="safety", message=reason, host_t_ns=max(t_ns, floor_ns),
                               device_t_ns=max(t_ns, floor_ns), detail={}) for reason, t_ns in over])
        if rig.tripped is not None and rig.tripped is not self._noted_trip:  # whenever it happened
            self._noted_trip = rig.tripped
            if not is_safety_trip(rig.tripped):
                put([self._event("sample_stop", rig.tripped)])
        for dev in (rig.platform, rig.arm, rig.gripper):
            if dev is None:
                continue
            records = dev.read_available()
            put(records)
            if records and dev is rig.platform:
                self.last_stage = records[-1]
            elif records and dev is rig.gripper:
                self.last_gripper = records[-1]
        if rig.camera is not None:
            detections: list[MarkerDetection] = rig.camera.read_available()
            put(detections)
            if self.save_images and detections and detections[-1].frame_seq != self._last_image_seq:
                image = rig.camera.latest_image()
                if image is not None:
                    d = detections[-1]
                    out.append((int(d.host_t_ns), partial(
                        w.write_image, image, d.device_t_ns, d.host_t_ns, d.frame_seq,
                        detections=[x for x in detections if x.frame_seq == d.frame_seq])))
                    self._last_image_seq = d.frame_seq
        out.sort(key=lambda item: item[0])  # stable: records of one time keep their order
        for _, write in out:
            write()
        self._drained_ns = now_ns = rig.clock.now_ns()
        self.frames.update(now_ns, None if self.last_gripper is None else float(self.last_gripper.position_mm))
        return carried_frames + frames, carried_wrenches + wrenches


def _describe(exc: BaseException) -> str:
    if isinstance(exc, KeyboardInterrupt):
        return "interrupted (Ctrl-C)"
    if isinstance(exc, Terminated):
        return str(exc) or "terminated"
    text = str(exc).strip().splitlines()
    if isinstance(exc, DeviceError) or type(exc).__name__ == "GuardTripped":
        if text:  # the message names the device (or the guard) and what happened
            return text[0]
    return f"{type(exc).__name__}: {text[0]}" if text else type(exc).__name__


def run_trial(rig: Rig, path: Path, labels: dict, metadata: dict, body: Callable[[TrialLog], None], *,
              identity: str | None = None, save_images: bool = False, live=None, slot_s: float = 0.0,
              max_lost_skin_frames: int | None = 0) -> TrialResult:
    """Run one trial into `path` (skipped when a complete file of the same identity is there).

    identity: the trial identity (protocols.identity), stored in the file's metadata.
    slot_s: where the trial starts in its campaign (trial_slot_s), for a simulated clock.
    live: a layerskin_exp.log.live.LiveView that also serves what the trial writes.
    max_lost_skin_frames: the most skin frames the trial may lose and still be complete (None:
    no limit); one that loses more is closed "incomplete: ..." and left as `<path>.partial`.
    Every outcome stores the devices' stream health over the trial (trial_health).

    body(log) drives the rig and calls log.drain() as the clock advances. If it raises (a device
    error, a refused command, Ctrl-C), motion is stopped first, the file is closed
    "aborted: <reason>" and left as `<path>.partial`, and the exception propagates.
    """
    path = Path(path)
    name = path.stem
    check_termination()
    existing = complete_session(path)
    check_no_conflict(path, identity, existing)
    lost = lost_skin_frames(existing.stream_health) if existing is not None else 0
    if existing is not None and over_the_limit(lost, max_lost_skin_frames):
        aside = set_aside(path, "over-limit")
        RUN_FILES.record(aside, "set_aside")
        log.warning("trial %s: the complete file there lost %d skin frames, more than this run's "
                    "max_lost_skin_frames=%d; moved to %s, recording the trial again", name, lost,
                    max_lost_skin_frames, aside.name)
        existing = None
    elif existing is not None:
        note = _missing_views(existing.metadata.get("config") or {}, metadata.get("config") or {})
        if note:
            log.warning("trial %s is already complete (%s); it is not run again", name, note)
        RUN_FILES.record(path, "already_complete")
        return TrialResult(name, labels, str(path), existing.outcome, skipped=True,
                           extra={"note": note} if note else {})
    if path.is_file():  # damaged, of this identity or of none that can be read: kept, not replaced
        aside = set_aside(path)
        RUN_FILES.record(aside, "set_aside")
        log.warning("trial %s: the file there is damaged (identity %s); moved to %s, recording the "
                    "trial again", name, "unreadable" if surviving_identity(aside) is None else "this run's",
                    aside.name)
    if identity is not None:
        metadata = {**metadata, "identity": identity}
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + PARTIAL_SUFFIX)
    log.info("trial %s -> %s", name, path)
    rig.begin_trial(labels, slot_s)
    health0 = device_health(rig)
    t0_ns = rig.clock.now_ns()
    offset, how = rig.log_time() or (None, "given")
    try:
        writer = SessionWriter(tmp, metadata=metadata, labels=labels, overwrite=True, epoch_offset_ns=offset,
                               epoch_how=how)
    except OSError:  # a full disk as the trial starts: its file is there, cut short
        if tmp.exists():
            RUN_FILES.record(tmp, "interrupted")
        raise
    writer.live = live
    trial = TrialLog(writer, rig, save_images)
    try:
        body(trial)
        trial.drain()
    except BaseException as exc:
        rig.stop_motion()
        reason = _describe(exc)
        try:
            trial.drain()
            # A device fault the rig latched (its watchdog stopped motion then), whichever error
            # ended the trial: a command to a hung device may fail before the loop sees the fault.
            first = rig.first_fault()
            detail = {} if first is None else {"fault": first[0], "detected_ns": int(first[1])}
            late = getattr(rig, "fault_check_late_ns", None)
            if first is not None and late is not None:
                detail["check_late_ns"] = int(late)  # the watchdog's check ran this late (host scheduling)
            trial.event("error", reason, **detail)
        except BaseException:  # noqa: BLE001 - the device may be gone; the file must still close
            pass
        try:
            writer.close(f"aborted: {reason}", stream_health=trial_health(health0, device_health(rig)))
        except OSError as closing:  # a full disk: what reached it stays, without its summary
            log.warning("trial %s: its file could not be closed (%s); what was written is kept as %s",
                        name, closing, tmp)
        RUN_FILES.record(tmp, "interrupted")
        log.warning("trial %s aborted: %s (kept as %s)", name, reason, tmp)
        raise
    health = trial_health(health0, device_health(rig))
    outcome = outcome_after(trial.safety_trip, health, max_lost_skin_frames, trial.safety_samples)
    if outcome.startswith(COMPLETE):
        writer.close(outcome, move_to=path, stream_health=health)  # renamed under the writer's lock, fsynced
        RUN_FILES.record(path, "written")
    else:  # ran to its end with data missing: kept beside, run again by a rerun
        writer.close(outcome, stream_health=health)
        RUN_FILES.record(tmp, "incomplete", outcome)
        path = tmp
    result = TrialResult(name, labels, str(path), outcome, duration_s=(rig.clock.now_ns() - t0_ns) / 1e9,
                         peak_fz_n=trial.peak_fz_n, peak_shear_n=trial.peak_shear_n,
                         stop_reason=trial.stop_reason)
    log.log(logging.INFO if outcome == COMPLETE else logging.WARNING, "trial %s", result.summary())
    return result


def _missing_views(recorded: dict, asked: dict) -> str:
    """What this run asks for that the complete file was recorded without (VIEW_KEYS)."""
    return ", ".join(f"recorded with {k}={recorded.get(k)!r}, asked {asked[k]!r}" for k in VIEW_KEYS
                     if asked.get(k) and recorded.get(k) != asked.get(k))
