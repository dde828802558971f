"""Force-calibration campaign on the three-axis platform with the F/T reference.

At each contact position: `press.repeats` normal presses to `press.target_normal_n`, then
`slide.repeats` shear slides from a `slide.preload_n` preload in a random in-plane direction,
with a random vertical offset: the vertical part of one straight move to the skin edge, or (with
`slide.z_ramp_mm` set) reached over the first z_ramp_mm of in-plane travel. A slide stops
at |(Fx, Fy)| >= `slide.shear_stop_n` ("shear_reached"), at the skin edge ("skin_edge"), or when
the normal-force guard trips ("force_limit"). One session file per trial; the plan (positions,
directions, offsets) follows from the seed and the trial's labels, so a resumed campaign plans
the same trials.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from hardware.interfaces import DeviceError
from hardware.rig import Rig
from layerskin_exp.config import ConfigError
from layerskin_exp.rig import SENSING_HALF_WIDTH_MM
from protocols.config import ForceCalibrationConfig, PositionsConfig
from protocols.identity import design_id, trial_identity, write_manifest
from protocols.loop import ControlLoop
from protocols.runner import (
    RUN_FILES,
    TrialLog,
    TrialResult,
    run_trial,
    trial_is_complete,
    trial_rng,
    trial_slot_s,
)
from protocols.safety import Safety
from protocols.stops import (
    DEPTH_LIMIT,
    FORCE_LIMIT,
    LOADING,
    SHEAR_REACHED,
    SKIN_EDGE,
    SLOW_ZONE,
    TARGET_REACHED,
    is_safety_trip,
    trip_name,
)

PROTOCOL = "force_calibration"


@dataclass(frozen=True)
class CalibrationTrial:
    position_index: int
    position_mm: tuple[float, float]
    kind: str  # "press" | "slide"
    repeat: int
    direction_rad: float | None = None
    z_offset_mm: float | None = None

    @property
    def name(self) -> str:
        return f"pos{self.position_index:03d}_{self.kind}{self.repeat}"

    @property
    def labels(self) -> dict:
        return {"protocol": PROTOCOL, "position_index": self.position_index,
                "position_mm": [float(v) for v in self.position_mm], "kind": self.kind, "repeat": self.repeat,
                "direction_rad": self.direction_rad, "z_offset_mm": self.z_offset_mm}


def campaign_root(cfg: ForceCalibrationConfig, config: dict) -> Path:
    """The design folder the campaign of `cfg` writes; config: the resolved config."""
    return Path(cfg.data_root) / PROTOCOL / design_id(config)


def plan_positions(cfg: PositionsConfig, seed: int) -> np.ndarray:
    """(count, 2) contact centres in mm, inside the sensing area less the margin.

    random: each position drawn from its own generator (seed, index), so the first k positions
    do not depend on count. grid: ceil(sqrt(count)) per side, row-major, first `count`.
    """
    half_mm = SENSING_HALF_WIDTH_MM - cfg.margin_mm
    if cfg.layout == "grid":
        n = int(np.ceil(np.sqrt(cfg.count)))
        axis = np.linspace(-half_mm, half_mm, n) if n > 1 else np.zeros(1)
        yy, xx = np.meshgrid(axis, axis, indexing="ij")
        return np.column_stack([xx.ravel(), yy.ravel()])[: cfg.count]
    return np.array([trial_rng(seed, PROTOCOL, "position", i).uniform(-half_mm, half_mm, 2)
                     for i in range(cfg.count)])


def plan_trials(cfg: ForceCalibrationConfig) -> list[CalibrationTrial]:
    """Every trial of the campaign, in run order."""
    trials: list[CalibrationTrial] = []
    for i, (x, y) in enumerate(plan_positions(cfg.positions, cfg.seed)):
        xy = (round(float(x), 4), round(float(y), 4))
        trials += [CalibrationTrial(i, xy, "press", r) for r in range(cfg.press.repeats)]
        for r in range(cfg.slide.repeats):
            rng = trial_rng(cfg.seed, PROTOCOL, "slide", i, r)
            direction = float(rng.uniform(0.0, 2 * np.pi))
            z_offset = float(rng.uniform(-cfg.slide.z_offset_mm, cfg.slide.z_offset_mm))
            trials.append(CalibrationTrial(i, xy, "slide", r, round(direction, 6), round(z_offset, 6)))
    return trials


def distance_to_edge_mm(start_xy: np.ndarray, direction_xy: np.ndarray, half_mm: float) -> float:
    """In-plane travel from start along the unit direction until |x| or |y| reaches half_mm."""
    with np.errstate(divide="ignore"):
        limits = np.where(direction_xy > 0, (half_mm - start_xy) / direction_xy,
                          np.where(direction_xy < 0, (-half_mm - start_xy) / direction_xy, np.inf))
    return float(max(0.0, limits.min()))


class PlatformControl:
    """Moves of the platform as one trial sees them: every command passes the safety checks,
    every wait advances the rig clock in control ticks and drains the streams into the log."""

    def __init__(self, rig: Rig, safety: Safety, cfg: ForceCalibrationConfig) -> None:
        self.safety, self.cfg = safety, cfg
        self.platform = rig.platform
        self.log: TrialLog | None = None
        self.loop: ControlLoop | None = None
        self._known_mm: np.ndarray | None = None  # last reported position in this trial

    def bind(self, log: TrialLog) -> PlatformControl:
        """Use this trial's log (and a control loop on it) from now on. Nothing known from an
        earlier trial is kept: a trial runs the same whether it comes first or after others."""
        self.log = log
        self._known_mm = None
        self.loop = ControlLoop(log, self.cfg.control_period_s, trial_timeout_s=self.cfg.trial_timeout_s)
        return self

    def position_mm(self) -> np.ndarray:
        """Latest reported tip position (3,) mm; waits a tick for the first report if need be."""
        if self.log.last_stage is None and self._known_mm is None:
            self.loop.tick()
        if self.log.last_stage is not None:
            self._known_mm = np.asarray(self.log.last_stage.position_mm, float)
        if self._known_mm is None:
            raise DeviceError("platform: no position received; is the platform streaming?")
        return self._known_mm

    def move(self, target_mm, speed_mm_s: float, stop_when=None) -> str | None:
        """Move to target; returns None when it got there, or why it stopped early.

        stop_when(wrenches) -> reason | None is checked each tick on the new F/T samples.
        A safety trip, during the move or while the stage stopped, returns its name (FORCE_LIMIT;
        the backend has already stopped the motion) and stays latched for the retract. Every
        other trip (a stop condition checked per sample) is acknowledged before this returns,
        whichever way the move ended, and the stage counts as standing (platform_speed_mm_s 0):
        the next move starts from a clear guard.
        """
        target_mm = np.asarray(target_mm, float)
        self.safety.check_platform_move(target_mm, speed_mm_s)
        distance_mm = float(np.linalg.norm(target_mm - self.position_mm()))
        rig = self.log.rig
        self.platform.move_to(target_mm, speed_mm_s)

        def step(_frames, wrenches):
            reason = stop_when(wrenches) if stop_when is not None else None
            if rig.tripped is not None and not self.safety.unloading:
                if reason is not None and trip_name(rig.tripped) == SLOW_ZONE:
                    # the sample that entered the zone also met the stop condition (a stiff contact,
                    # or samples read late on a busy host): the stage has stopped for the zone and the
                    # move is done; going on at a crawl would press past the target into the guard
                    return "zone_stop", reason
                return "trip", rig.tripped
            if reason is not None:
                return "stop", reason
            return None if self.platform.is_moving() else ("arrived", None)

        kind, reason = self.loop.until(step, 1.5 * distance_mm / speed_mm_s + 2.0,
                                       f"platform move to {np.round(target_mm, 3).tolist()} mm")
        # From here the stage stands or brakes, so no fast move is under way: samples it reads while
        # braking or late (the load goes on rising meanwhile, a busy host reads them late) must not
        # trip the slow zone or a press's stage stop (seen under load: SafetyError before the next
        # move; on loopback a "slow_zone" stop during every hold). Only a safety limit still trips.
        self.safety.platform_speed_mm_s = 0.0
        if kind == "stop":
            self.platform.stop()
        if kind != "arrived":
            self.wait_stopped()
        if self.safety.unloading:  # a retract ignores trips; lift acknowledges the one it started from
            return reason
        latched = rig.tripped
        if is_safety_trip(latched):  # kept latched: the retract (lift) acknowledges it
            return trip_name(latched)
        if latched is not None:
            # a stop condition checked per sample, not a fault: the move's own trip, or one that landed
            # while the stage braked; cleared whichever path ended the move, so the next move may start
            rig.clear_trip(latched)
        if kind == "trip" and trip_name(reason) == SLOW_ZONE:  # near the limit: go on at a crawl
            return self.move(target_mm, min(speed_mm_s, self.cfg.safety.slow_zone_speed_mm_s), stop_when)
        return reason

    def wait_stopped(self) -> None:
        self.loop.wait(self.platform.is_moving, 2.0, "platform stop")

    def hold(self, duration_s: float) -> None:
        self.loop.hold(duration_s)

    def lift(self, xy_mm) -> None:
        """Retract straight up to the clearance height; allowed while the force guard is tripped.
        Moving away from the skin only unloads it, so neither the force limit nor the slow zone
        stops it (from a hold above the zone the retract went on at a crawl: 0.3 mm/s)."""
        self.log.event("phase", "retract")
        target = np.array([*xy_mm, self.cfg.approach.clearance_mm], float)
        tripped = self.log.rig.tripped is not None
        self.safety.unloading = True
        try:
            self.move(target, self.cfg.approach.travel_speed_mm_s)
        finally:
            self.safety.unloading = False
            if tripped:
                self.log.rig.clear_trip()

    def press(self, target_n: float, stop_reason_on_target: bool) -> str:
        """Press down at the contact point until Fz >= target_n; returns the stop reason.

        The press runs in stages (`press_stages`), each slower than the one before; a stage ends on
        the F/T sample that crosses the next stage's force (a backend guard with
        press.stop_on_sample, else at the next tick), the last on the sample that reaches the target.
        """
        cfg = self.cfg
        contact = {"seen": False}

        def check(end_n: float):
            def stop_when(wrenches) -> str | None:
                if not wrenches:
                    return None
                fz_n = max(float(w.force_n[2]) for w in wrenches)
                if not contact["seen"] and fz_n >= cfg.approach.contact_force_n:
                    contact["seen"] = True
                    self.log.event("contact", "contact", fz_n=fz_n)
                if fz_n >= target_n:
                    return TARGET_REACHED
                return LOADING if fz_n >= end_n else None
            return stop_when

        def on_sample(end_n: float, reason: str):
            """Checked by the backend on every F/T sample. Only while the stage moves: a sample read
            after the stop was acknowledged (the load rises while the stage brakes) would otherwise
            stop a standing stage again and trip before the next stage's move."""
            safety = self.safety
            return lambda sample: reason if safety.platform_speed_mm_s > 0 and sample.force_n[2] >= end_n else None

        x, y = self.position_mm()[:2]
        bottom = np.array([x, y, cfg.safety.platform_min_mm[2]])
        rig = self.log.rig
        reason = None
        for speed_mm_s, end_n in press_stages(cfg.press, target_n):
            guard = on_sample(end_n, TARGET_REACHED if end_n >= target_n else LOADING)
            if cfg.press.stop_on_sample:
                rig.add_guard(guard)
            try:
                reason = self.move(bottom, speed_mm_s, check(end_n))
            finally:
                rig.remove_guard(guard)
            if reason != LOADING:
                break
        reason = reason or DEPTH_LIMIT
        if reason != TARGET_REACHED or stop_reason_on_target:
            fz = None if self.log.last_wrench is None else float(self.log.last_wrench.force_n[2])
            self.log.stop(reason, fz_n=fz, tripped=self.log.rig.tripped)
        return reason


def press_stages(press, target_n: float) -> list[tuple[float, float]]:
    """The stages of a press to target_n, as (speed mm/s, force N where the stage ends): from
    contact at press.speed_mm_s, above press.slow_above_n at load_speed_mm_s, above final_fraction
    x the target at final_speed_mm_s, each no faster than the one before; stages of one speed are
    one stage (no stop between them). The last ends at the target."""
    changes = sorted((min(f, target_n), v) for f, v in (
        (0.0, press.speed_mm_s), (press.slow_above_n, press.load_speed_mm_s),
        (press.final_fraction * target_n, press.final_speed_mm_s)))
    starts: list[tuple[float, float]] = []  # (speed, force where it starts), each slower than the last
    for start_n, speed in changes:
        if start_n < target_n and (not starts or speed < starts[-1][0]):
            starts.append((speed, start_n))
    ends = [start_n for _, start_n in starts[1:]] + [target_n]
    return [(speed, end_n) for (speed, _), end_n in zip(starts, ends, strict=True)]


def run_press(ctl: PlatformControl, trial: CalibrationTrial) -> None:
    cfg = ctl.cfg
    ctl.log.event("phase", "press", target_n=cfg.press.target_normal_n)
    reason = ctl.press(cfg.press.target_normal_n, stop_reason_on_target=True)
    if reason == TARGET_REACHED:
        ctl.log.event("phase", "hold")
        ctl.hold(cfg.press.hold_s)
    ctl.lift(trial.position_mm)


def run_slide(ctl: PlatformControl, trial: CalibrationTrial) -> None:
    cfg, log = ctl.cfg, ctl.log
    log.event("phase", "press", target_n=cfg.slide.preload_n)
    reason = ctl.press(cfg.slide.preload_n, stop_reason_on_target=False)
    if reason == FORCE_LIMIT:
        ctl.lift(trial.position_mm)
        return
    start = ctl.position_mm()
    direction = np.array([np.cos(trial.direction_rad), np.sin(trial.direction_rad)])
    travel_mm = distance_to_edge_mm(start[:2], direction, SENSING_HALF_WIDTH_MM - cfg.slide.edge_margin_mm)
    z_ramp = travel_mm if cfg.slide.z_ramp_mm is None else cfg.slide.z_ramp_mm
    ramp_mm = min(z_ramp, travel_mm)
    z_lo, z_hi = cfg.safety.platform_min_mm[2], cfg.approach.clearance_mm
    z_end = float(np.clip(start[2] + trial.z_offset_mm * ramp_mm / max(z_ramp, 1e-9), z_lo, z_hi))
    waypoints = [np.array([*(start[:2] + ramp_mm * direction), z_end])]
    if ramp_mm < travel_mm:
        waypoints.append(np.array([*(start[:2] + travel_mm * direction), z_end]))
    log.event("phase", "slide", direction_rad=trial.direction_rad, z_offset_mm=trial.z_offset_mm,
              travel_mm=travel_mm, start_mm=start.tolist())

    def shear(wrenches) -> str | None:
        if wrenches and max(np.hypot(w.force_n[0], w.force_n[1]) for w in wrenches) >= cfg.slide.shear_stop_n:
            return SHEAR_REACHED
        return None

    reason = None
    for wp in waypoints:
        if travel_mm <= 0:
            break
        reason = ctl.move(wp, cfg.slide.speed_mm_s, shear)
        if reason is not None:
            break
    reason = reason or SKIN_EDGE
    last = log.last_wrench
    log.stop(reason, fz_n=None if last is None else float(last.force_n[2]),
             shear_n=None if last is None else float(np.hypot(*last.force_n[:2])),
             position_mm=ctl.position_mm().tolist())
    ctl.lift(ctl.position_mm()[:2])


def run_campaign(cfg: ForceCalibrationConfig, rig: Rig, metadata: dict, live=None) -> list[TrialResult]:
    """Run every trial not yet complete under cfg.data_root; returns the results of this run.
    live: a LiveView that also serves each trial as it is written."""
    if rig.platform is None or rig.ft is None:
        raise ConfigError(f"hardware: backend {rig.backend!r} gave no platform/F-T sensor; the force "
                          "calibration needs the platform setup")
    safety = Safety(cfg.safety, rig)
    ctl = PlatformControl(rig, safety, cfg)
    root = campaign_root(cfg, metadata["config"])
    trials = plan_trials(cfg)
    identity = {t.name: trial_identity(metadata["config"], t.labels) for t in trials}
    # trial_is_complete refuses a conflicting file: before the first trial, not half-way through
    todo = []
    for t in trials:
        if trial_is_complete(root / f"{t.name}.mcap", identity[t.name], cfg.max_lost_skin_frames):
            RUN_FILES.record(root / f"{t.name}.mcap", "already_complete")
        else:
            todo.append(t)
    if todo:
        write_manifest(root, metadata["config"])
    results: list[TrialResult] = []
    with tqdm(total=len(trials), initial=len(trials) - len(todo), unit="trial", desc=PROTOCOL,
              disable=not cfg.progress, dynamic_ncols=True) as bar:
        if len(todo) < len(trials):
            tqdm.write(f"{PROTOCOL}: {len(trials) - len(todo)} of {len(trials)} trials already complete "
                       f"in {root}; running the other {len(todo)}")
        for trial in todo:
            slot_s = trial_slot_s(trials.index(trial), cfg.trial_timeout_s)

            def body(log: TrialLog, trial=trial) -> None:
                ctl.bind(log)
                log.event("phase", "approach", position_mm=list(trial.position_mm))
                clearance = np.array([*trial.position_mm, cfg.approach.clearance_mm])
                here = ctl.position_mm()
                if here[2] < cfg.approach.clearance_mm - 1e-6:  # never travel sideways in contact
                    ctl.move([here[0], here[1], cfg.approach.clearance_mm], cfg.approach.travel_speed_mm_s)
                ctl.move(clearance, cfg.approach.travel_speed_mm_s)
                if cfg.tare_each_trial:
                    rig.ft.tare()
                (run_press if trial.kind == "press" else run_slide)(ctl, trial)

            meta = {**metadata, "protocol": PROTOCOL, "plan": trial.labels}
            result = run_trial(rig, root / f"{trial.name}.mcap", trial.labels, meta, body,
                               identity=identity[trial.name], live=live, slot_s=slot_s,
                               max_lost_skin_frames=cfg.max_lost_skin_frames)
            results.append(result)
            bar.update(1)
            if cfg.progress:
                tqdm.write(result.summary())
    return results
