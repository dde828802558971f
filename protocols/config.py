"""Schemas of the protocol apps, stored in Hydra's ConfigStore at import.

Two primary configs (`conf/force_calibration.yaml`, `conf/grip_depth.yaml`) and one group
(`conf/trajectory/`). Every range check lives in `__post_init__` via `require`, so
`layerskin_exp.config.validate(cfg)` refuses a bad override before any device is touched.
Safety limits are part of the config (the framework enforces them, see `protocols/safety.py`);
each protocol setting is also checked against them here.
"""

from __future__ import annotations

import math
import tempfile
from dataclasses import dataclass, field, fields, is_dataclass
from pathlib import Path
from typing import Any

from hydra.core.config_store import ConfigStore
from omegaconf import MISSING

# The groups the protocol configs compose: importing their schema modules stores them for Hydra.
import hardware.config  # noqa: F401
import layerskin_exp.sim.config  # noqa: F401
from layerskin_exp import rig
from layerskin_exp.config import SkinConfig, require, require_host, require_seed

# Hard ceilings no config can raise: what the skin, the platform, the UR5e and the Hand-E can do
# safely on this rig. Checked when the config is validated, before any device connects.
HARD = {
    # The study's limit is 6 N (|Fz| reached 6.2 N); 10 N on the r 2.5 mm indenter already drives
    # the 2.9 mm stack near full compression, past which the lattice and the FSR sheets are at risk.
    "max_normal_force_n": 10.0,
    # The platform only needs to reach the 24 x 24 mm area (+ 3 mm) and a few mm above it; below
    # -3 mm the indenter would bottom out through the 2.9 mm stack onto the support.
    "platform_min_mm": (-15.0, -15.0, -3.0),
    "platform_max_mm": (15.0, 15.0, 20.0),
    "max_platform_speed_mm_s": 20.0,
    # UR5e moving a gripped rod: far below ISO 10218-1's 250 mm/s reduced speed; the protocol
    # moves a few mm at 2 mm/s and 1.5 deg/s.
    "max_arm_speed_mm_s": 50.0,
    "max_arm_angular_speed_deg_s": 30.0,
    "arm_max_offset_mm": 50.0,
    "arm_max_rotation_deg": 90.0,
    # Robotiq Hand-E: 20-150 mm/s jaw speed, 50 mm stroke.
    "max_gripper_speed_mm_s": 150.0,
    "max_grip_depth_mm": 50.0,
    "gripper_stroke_mm": 50.0,
    # Summed counts of both layers near full scale mean most taxels are saturated: the sensor no
    # longer measures what it carries.
    "max_skin_load_fraction": 0.8,
}
# A 424 Hz rig: a loop faster than 1 ms drains nothing new; slower than 100 ms misses stops.
CONTROL_PERIOD_S = (1e-3, 0.1)
TRIAL_TIMEOUT_S = (1.0, 3600.0)
# Ceilings of the counts a config sets, checked before any device connects: a few zeros too many
# otherwise plan a campaign that would run for years, held in memory before its first trial.
# Session files are named posNNN (three digits); 1000 positions is ten times the study's 100.
MAX_POSITIONS = 1000
# Per position and kind (the study: 5 presses, 4 slides); a hundred presses on one spot measure
# the wear of the cover there, not the sensor.
MAX_REPEATS = 100
# Contact is confirmed over this many frames while the jaws close on: 100 frames (0.24 s at
# 424 Hz) already add ~5 mm of closure at 20 mm/s to the commanded grip depth.
MAX_CONSECUTIVE_FRAMES = 100
# What both layers read at full scale: a higher contact threshold is never crossed.
MAX_SKIN_SUM_COUNTS = len(rig.LAYERS) * rig.N_TAXELS**2 * rig.ADC_MAX
# The study ran 7 trials per grip depth and motion; a trial index past 999 is a typo (1000 trials of
# one condition are ~33 h of arm motion), and past 2**32 it would draw another trial's numbers.
MAX_TRIAL = 999
# A trial whose skin stream lost more frames than max_lost_skin_frames is incomplete. A limit is a
# count of frames within one trial: a million is 39 min of frames at 424 Hz, past any sensible one.
MAX_LOST_SKIN_FRAMES = 1_000_000
# The skin baseline averages the frames of approach.baseline_s; with fewer, its noise (or, with
# none, a baseline of 0 counts) decides when contact is "detected".
MIN_BASELINE_FRAMES = 5


def _check_data_root(data_root: str) -> None:
    """The session files can be written there: found now, not after the devices connect."""
    require(bool(data_root), "data_root", data_root, "give a folder for the session files")
    path = Path(data_root).absolute()
    require(not path.exists() or path.is_dir(), "data_root", data_root,
            "exists and is not a folder; give a folder for the session files")
    existing = next(p for p in (path, *path.parents) if p.exists())
    require(existing.is_dir(), "data_root", data_root, f"{existing} is not a folder; give a writable folder")
    try:  # a probe file, removed at once: permissions, read-only mounts and /proc all answer here
        with tempfile.TemporaryFile(dir=existing):
            pass
    except OSError as exc:
        require(False, "data_root", data_root,
                f"cannot write in {existing} ({exc.strerror or exc}); give a writable folder")


def _check_finite(node, prefix: str = "", skip: tuple[str, ...] = ("hardware", "skin", "sim")) -> None:
    """Every number in a protocol config is finite (inf and nan pass `x > 0`-style checks or none)."""
    for f in fields(node):
        if f.name in skip:
            continue
        value, key = getattr(node, f.name), f"{prefix}{f.name}"
        if is_dataclass(value):
            _check_finite(value, f"{key}.", ())
        elif isinstance(value, float):
            require(math.isfinite(value), key, value, "must be a finite number")
        elif isinstance(value, list | tuple):
            require(all(math.isfinite(v) for v in value if isinstance(v, float)), key, value,
                    "must hold finite numbers")


def _check_count(key: str, value: int, low: int, ceiling: int, why: str) -> None:
    require(low <= value <= ceiling, key, value, f"must be in [{low}, {ceiling}] ({why})")


def _check_lost_frames(value: int) -> None:
    _check_count("max_lost_skin_frames", value, 0, MAX_LOST_SKIN_FRAMES,
                 "skin frames one trial may lose and still be complete; 0: none")


def _check_live(cfg) -> None:
    """The live view's port, address and who it lets in."""
    port = cfg.live_port
    require(port == 0 or 1024 <= port <= 65535, "live_port", port,
            "must be a TCP port in [1024, 65535] (lower ones need root), or 0 for any free port")
    require_host("live_host", cfg.live_host)
    require(cfg.live_token is None or (isinstance(cfg.live_token, str) and len(cfg.live_token) >= 8),
            "live_token", "<hidden>", "must be at least 8 characters, or null")
    loopback = cfg.live_host in ("127.0.0.1", "::1", "localhost")
    require(loopback or cfg.live_token is not None, "live_host", cfg.live_host,
            "serves the run beyond this machine: set live_token too (remote viewers add ?token=<it> to the URL)")
    for name in cfg.live_allowed_hosts or ():
        require_host("live_allowed_hosts", name)


def _check_motion_time(key: str, speed: float, waypoints: list[float], unit: str, timeout_s: float) -> None:
    """The trajectory, from the start through every waypoint at `speed`, fits in the trial's time."""
    path = sum(abs(b - a) for a, b in zip([0.0, *waypoints], waypoints, strict=False))
    require(path / speed <= timeout_s, key, speed,
            f"{path:g} {unit} of waypoints at this speed take {path / speed:.3g} s, more than "
            f"trial_timeout_s={timeout_s:g}; raise the speed (or trial_timeout_s)")


def _check_duration(key: str, value: float, timeout_s: float) -> None:
    require(0 <= value <= timeout_s, key, value, f"must be in [0, trial_timeout_s={timeout_s}] s")


def _arm_accel_cap(cfg) -> tuple[float, str]:
    """The arm driver's acceleration cap (m/s^2) and its key, on this config's backend."""
    ur5e = getattr(cfg.hardware, "ur5e", None)
    if ur5e is not None:
        return float(ur5e.max_accel_m_s2), "hardware.ur5e.max_accel_m_s2"
    arm = getattr(getattr(cfg.sim, "rig", None), "arm", None)
    if arm is not None:
        return float(arm.max_accel_m_s2), "sim.rig.arm.max_accel_m_s2"
    return 1.5, "max_accel_m_s2"


def _check_fault_devices(hardware, setup: str) -> None:
    """Fault injection names only emulators this protocol's setup runs (loopback backend)."""
    faults = getattr(hardware, "faults", None)
    if not faults:
        return
    from hardware.loopback import SETUP_DEVICES

    for device in faults:
        require(device in SETUP_DEVICES[setup], f"hardware.faults.{device}", faults[device],
                f"no {device} emulator on the {setup} setup; choose among {list(SETUP_DEVICES[setup])}")


@dataclass
class SafetyConfig:
    """Limits the framework enforces on every backend (checked before each motion command,
    and per F/T sample for the normal force)."""

    max_normal_force_n: float = 6.0
    # Above this fraction of the normal-force limit a platform move faster than slow_zone_speed
    # is stopped and goes on at that speed, so the stage brakes from a crawl if the limit trips.
    slow_zone_fraction: float = 0.9
    slow_zone_speed_mm_s: float = 0.3
    platform_min_mm: list[float] = field(default_factory=lambda: [-13.0, -13.0, -2.5])
    platform_max_mm: list[float] = field(default_factory=lambda: [13.0, 13.0, 10.0])
    max_platform_speed_mm_s: float = 10.0
    max_arm_speed_mm_s: float = 10.0
    max_arm_angular_speed_deg_s: float = 10.0
    arm_max_offset_mm: float = 15.0  # TCP distance from where the trial's motion started
    arm_max_rotation_deg: float = 40.0
    max_gripper_speed_mm_s: float = 50.0
    max_grip_depth_mm: float = 20.0
    # The grip rig has no F/T sensor: its load guard is the skin's summed counts (both layers) as a
    # fraction of full scale, checked on every frame. The study's deepest grip (15 mm) loads the
    # simulated skin to ~0.2; 0.5 leaves room for it while stopping a closure that crushes the sensor.
    max_skin_load_fraction: float = 0.5

    def __post_init__(self) -> None:
        require(len(self.platform_min_mm) == 3 and len(self.platform_max_mm) == 3, "safety.platform_min_mm",
                self.platform_min_mm, "bounds need three values (x, y, z) in mm")
        require(all(lo < hi for lo, hi in zip(self.platform_min_mm, self.platform_max_mm, strict=True)),
                "safety.platform_max_mm", self.platform_max_mm, "each upper bound must exceed the lower one")
        for key in ("max_platform_speed_mm_s", "max_arm_speed_mm_s", "max_arm_angular_speed_deg_s",
                    "arm_max_offset_mm", "arm_max_rotation_deg", "max_gripper_speed_mm_s",
                    "max_grip_depth_mm", "max_normal_force_n"):
            value = getattr(self, key)
            require(0 < value <= HARD[key], f"safety.{key}", value,
                    f"must be > 0 and at most {HARD[key]} (a hard ceiling of this rig; no config can raise it)")
        require(0.5 <= self.slow_zone_fraction < 1.0, "safety.slow_zone_fraction", self.slow_zone_fraction,
                "must be in [0.5, 1) of safety.max_normal_force_n")
        require(0 < self.slow_zone_speed_mm_s <= 1.0, "safety.slow_zone_speed_mm_s", self.slow_zone_speed_mm_s,
                "must be in (0, 1] mm/s")
        require(0 < self.max_skin_load_fraction <= HARD["max_skin_load_fraction"], "safety.max_skin_load_fraction",
                self.max_skin_load_fraction, f"must be in (0, {HARD['max_skin_load_fraction']}] of full scale")
        for i, (lo, hi) in enumerate(zip(self.platform_min_mm, self.platform_max_mm, strict=True)):
            require(lo >= HARD["platform_min_mm"][i], "safety.platform_min_mm", self.platform_min_mm,
                    f"must stay within the platform's hard envelope {list(HARD['platform_min_mm'])} mm")
            require(hi <= HARD["platform_max_mm"][i], "safety.platform_max_mm", self.platform_max_mm,
                    f"must stay within the platform's hard envelope {list(HARD['platform_max_mm'])} mm")


def _check_speed(key: str, value: float, cap: float, cap_key: str) -> None:
    require(0 < value <= cap, key, value, f"speed must be > 0 and at most {cap_key}={cap}")


# --------------------------------------------------------------------------------------------
# Force calibration
# --------------------------------------------------------------------------------------------


@dataclass
class PositionsConfig:
    """Where on the 24 x 24 mm area the indenter presses."""

    layout: str = "random"  # "random" (uniform) or "grid" (row-major, ceil(sqrt(count)) per side)
    count: int = 100
    margin_mm: float = 2.0  # keep contact centres this far inside the sensing area

    def __post_init__(self) -> None:
        require(self.layout in ("random", "grid"), "positions.layout", self.layout, "use 'random' or 'grid'")
        _check_count("positions.count", self.count, 1, MAX_POSITIONS,
                     "files are named posNNN; run a larger campaign as several data_roots")
        require(0 <= self.margin_mm < rig.SENSING_HALF_WIDTH_MM, "positions.margin_mm", self.margin_mm,
                f"must be in [0, {rig.SENSING_HALF_WIDTH_MM}) mm")


@dataclass
class ApproachConfig:
    clearance_mm: float = 0.3  # tip height above the cover between trials
    travel_speed_mm_s: float = 8.0  # moves in the air
    contact_force_n: float = 0.05  # Fz above this logs the "contact" event


@dataclass
class PressConfig:
    repeats: int = 5
    target_normal_n: float = 5.0
    speed_mm_s: float = 2.0
    # Above this load the press continues at load_speed_mm_s (slower where a stiff design makes
    # the platform's braking distance worth a lot of force); the default loads at full speed.
    slow_above_n: float = 0.5
    load_speed_mm_s: float = 2.0
    # Above final_fraction x the target the press creeps at final_speed_mm_s. The stage stops
    # some time after the sample that meets the target (on loopback ~25 ms unloaded: the host
    # reads the sample, GRBL takes the feed hold, the stage brakes), and the load goes on rising at
    # speed x stiffness meanwhile: ~0.8 N at 2 mm/s on the default stack (~15 N/mm at 5 N), most of
    # the 1 N between the target and the force limit. Creeping, that is ~0.2 N. 1.0: no creep.
    final_fraction: float = 0.6
    final_speed_mm_s: float = 0.5
    # Stop on the F/T sample that reaches the target or ends a stage (a backend guard), not at the
    # next tick.
    stop_on_sample: bool = True
    hold_s: float = 0.2

    def __post_init__(self) -> None:
        require(self.target_normal_n > 0, "press.target_normal_n", self.target_normal_n, "must be > 0 N")
        require(self.speed_mm_s > 0, "press.speed_mm_s", self.speed_mm_s, "must be > 0")
        require(self.load_speed_mm_s > 0, "press.load_speed_mm_s", self.load_speed_mm_s, "must be > 0")
        require(self.slow_above_n >= 0, "press.slow_above_n", self.slow_above_n, "must be >= 0 N")
        require(0 < self.final_fraction <= 1, "press.final_fraction", self.final_fraction,
                "must be in (0, 1] of the target (1: no creep before it)")
        require(self.final_speed_mm_s > 0, "press.final_speed_mm_s", self.final_speed_mm_s, "must be > 0")
        require(self.hold_s >= 0, "press.hold_s", self.hold_s, "must be >= 0 s")


@dataclass
class SlideConfig:
    repeats: int = 4
    preload_n: float = 3.0  # normal load the slide starts from
    z_offset_mm: float = 0.5  # vertical offset drawn uniform in [-z_offset_mm, z_offset_mm]
    # in-plane travel over which the vertical offset is applied; None: the offset is the vertical
    # part of the slide's one straight move to the edge (the study's "random displacement along Z")
    z_ramp_mm: float | None = None
    speed_mm_s: float = 2.0
    shear_stop_n: float = 2.0  # stop when |(Fx, Fy)| reaches this
    edge_margin_mm: float = 0.5  # "skin edge": tip this far inside the sensing area


@dataclass
class ForceCalibrationConfig:
    hardware: Any = MISSING
    skin: Any = MISSING
    sim: Any = None
    safety: SafetyConfig = field(default_factory=SafetyConfig)
    positions: PositionsConfig = field(default_factory=PositionsConfig)
    approach: ApproachConfig = field(default_factory=ApproachConfig)
    press: PressConfig = field(default_factory=PressConfig)
    slide: SlideConfig = field(default_factory=SlideConfig)
    seed: int = 0
    data_root: str = "data"
    control_period_s: float = 0.01  # protocol loop tick; the force limit is checked per F/T sample
    trial_timeout_s: float = 60.0
    tare_each_trial: bool = True
    # The most skin frames a trial may lose (sequence gaps the skin driver counts, plus frames its
    # full buffer let go) and still be complete. 0 (default): any lost frame makes the trial
    # "incomplete: <n> skin frames lost ..."; it is kept as .partial and a rerun records it again.
    # Every trial stores all devices' stream-health counters whatever this is (`inspect` shows them).
    max_lost_skin_frames: int = 0
    progress: bool = True
    live: bool = False  # serve the run to Foxglove over WebSocket on 127.0.0.1:live_port
    live_port: int = 8765
    live_hold: bool = False  # with live: keep serving after the run until Ctrl-C
    # Where the live view listens (another address than loopback needs live_token); the host names
    # a client's Host and Origin headers may give (null: this machine and the Foxglove web app);
    # live_token: a client adding ?token=<it> to the URL is let in whatever it sends (a remote viewer)
    live_host: str = "127.0.0.1"
    live_allowed_hosts: list[str] | None = None
    live_token: str | None = None

    def __post_init__(self) -> None:
        s = self.safety
        for key, value in (("press.repeats", self.press.repeats), ("slide.repeats", self.slide.repeats)):
            _check_count(key, value, 0, MAX_REPEATS, "repeats on one spot wear the cover there; add positions instead")
        require(self.press.repeats + self.slide.repeats > 0, "press.repeats", self.press.repeats,
                "press.repeats + slide.repeats must be > 0")
        require(0 < self.press.target_normal_n < s.max_normal_force_n, "press.target_normal_n",
                self.press.target_normal_n, f"must be > 0 and below safety.max_normal_force_n={s.max_normal_force_n}")
        require(0 < self.slide.preload_n < s.max_normal_force_n, "slide.preload_n", self.slide.preload_n,
                f"must be > 0 and below safety.max_normal_force_n={s.max_normal_force_n}")
        require(0 < self.slide.shear_stop_n, "slide.shear_stop_n", self.slide.shear_stop_n, "must be > 0 N")
        require(0 <= self.slide.z_offset_mm <= 2.0, "slide.z_offset_mm", self.slide.z_offset_mm, "must be in [0, 2] mm")
        require(self.slide.z_ramp_mm is None or self.slide.z_ramp_mm > 0, "slide.z_ramp_mm", self.slide.z_ramp_mm,
                "must be > 0 mm, or null (spread over the whole slide)")
        require(0 <= self.slide.edge_margin_mm < rig.SENSING_HALF_WIDTH_MM, "slide.edge_margin_mm",
                self.slide.edge_margin_mm, f"must be in [0, {rig.SENSING_HALF_WIDTH_MM}) mm")
        require(self.press.hold_s >= 0, "press.hold_s", self.press.hold_s, "must be >= 0 s")
        require(self.approach.contact_force_n > 0, "approach.contact_force_n", self.approach.contact_force_n,
                "must be > 0 N")
        for key, value in (("press.speed_mm_s", self.press.speed_mm_s), ("slide.speed_mm_s", self.slide.speed_mm_s),
                           ("approach.travel_speed_mm_s", self.approach.travel_speed_mm_s)):
            _check_speed(key, value, s.max_platform_speed_mm_s, "safety.max_platform_speed_mm_s")
        edge = rig.SENSING_HALF_WIDTH_MM - self.slide.edge_margin_mm
        require(all(lo <= -edge and hi >= edge for lo, hi in zip(s.platform_min_mm[:2], s.platform_max_mm[:2],
                                                                  strict=True)),
                "slide.edge_margin_mm", self.slide.edge_margin_mm,
                "the skin edge lies outside safety.platform_min_mm/max_mm; raise the margin or widen the bounds")
        require(s.platform_min_mm[2] < 0 < self.approach.clearance_mm <= s.platform_max_mm[2],
                "approach.clearance_mm", self.approach.clearance_mm,
                "must be > 0 and within safety.platform_max_mm[2] (and the z bounds must allow pressing below 0)")
        require(CONTROL_PERIOD_S[0] <= self.control_period_s <= CONTROL_PERIOD_S[1], "control_period_s",
                self.control_period_s, f"must be in [{CONTROL_PERIOD_S[0]}, {CONTROL_PERIOD_S[1]}] s")
        require(TRIAL_TIMEOUT_S[0] <= self.trial_timeout_s <= TRIAL_TIMEOUT_S[1], "trial_timeout_s",
                self.trial_timeout_s, f"must be in [{TRIAL_TIMEOUT_S[0]}, {TRIAL_TIMEOUT_S[1]}] s")
        _check_duration("press.hold_s", self.press.hold_s, self.trial_timeout_s)
        require_seed("seed", self.seed)
        _check_lost_frames(self.max_lost_skin_frames)
        _check_live(self)
        _check_finite(self)
        _check_fault_devices(self.hardware, "platform")
        _check_data_root(self.data_root)


# --------------------------------------------------------------------------------------------
# Grip depth
# --------------------------------------------------------------------------------------------


@dataclass
class TranslationConfig:
    """Arm translation: the TCP moves `waypoints_mm` along `axis` (base frame; X0 = [1, 0, 0])."""

    waypoints_mm: list[float] = field(default_factory=lambda: [0.0, 5.0, 0.0, -5.0, 0.0])
    speed_mm_s: float = 2.0
    accel_mm_s2: float = 100.0
    axis: list[float] = field(default_factory=lambda: [1.0, 0.0, 0.0])


@dataclass
class TorsionConfig:
    """Gripper torsion: the tool turns `waypoints_deg` about `axis` (tool frame: the skin normal),
    about the TCP."""

    waypoints_deg: list[float] = field(default_factory=lambda: [0.0, 25.0, 0.0, -25.0, 0.0])
    speed_deg_s: float = 1.5
    accel_rad_s2: float = 0.1  # the arm's angular acceleration (UR speedL's rotational part)
    axis: list[float] = field(default_factory=lambda: [0.0, 1.0, 0.0])


# Keys of the trajectory before units were in their names: refused, naming the new key.
RENAMED_KEYS = {
    "trajectory.speed": "trajectory.translation.speed_mm_s (mm/s) or trajectory.torsion.speed_deg_s (deg/s)",
    "trajectory.waypoints": "trajectory.translation.waypoints_mm or trajectory.torsion.waypoints_deg",
    "trajectory.accel_mm_s2": "trajectory.translation.accel_mm_s2 or trajectory.torsion.accel_rad_s2",
    "trajectory.axis": "trajectory.translation.axis or trajectory.torsion.axis",
}


@dataclass
class TrajectoryConfig:
    """The motion imposed after the grip: `motion` picks which of the two runs.

    Both motions' parameters are always there (the `trajectory=translation|torsion` presets only
    set `motion`), so a trial's design does not depend on which motion it runs.
    """

    motion: str = "translation"
    translation: TranslationConfig = field(default_factory=TranslationConfig)
    torsion: TorsionConfig = field(default_factory=TorsionConfig)

    def __post_init__(self) -> None:
        require(self.motion in ("translation", "torsion"), "trajectory.motion", self.motion,
                "use 'translation' or 'torsion'")
        for key, points in (("trajectory.translation.waypoints_mm", self.translation.waypoints_mm),
                            ("trajectory.torsion.waypoints_deg", self.torsion.waypoints_deg)):
            require(len(points) >= 1 and all(math.isfinite(w) for w in points), key, points,
                    "give at least one finite waypoint")
        for key, axis in (("trajectory.translation.axis", self.translation.axis),
                          ("trajectory.torsion.axis", self.torsion.axis)):
            require(len(axis) == 3 and all(math.isfinite(a) for a in axis) and sum(a * a for a in axis) > 0,
                    key, axis, "must be a finite non-zero 3-vector")

    @property
    def waypoints(self) -> list[float]:
        """The waypoints of the motion that runs (mm for translation, degrees for torsion)."""
        return list(self.translation.waypoints_mm if self.motion == "translation" else self.torsion.waypoints_deg)

    @property
    def axis(self) -> list[float]:
        return list(self.translation.axis if self.motion == "translation" else self.torsion.axis)


@dataclass
class GripApproachConfig:
    start_opening_mm: float = 40.0  # jaws open this far before the approach
    min_opening_mm: float = 0.0  # the approach gives up (no contact) here
    speed_mm_s: float = 20.0  # the Hand-E moves at 20..150 mm/s
    force_pct: float = 20.0
    threshold_counts: int = 500  # sum over both layers, after baseline subtraction
    consecutive_frames: int = 5
    baseline_s: float = 0.05  # skin frames averaged, jaws open, for the baseline


@dataclass
class GripCloseConfig:
    speed_mm_s: float = 20.0
    force_pct: float = 50.0
    settle_s: float = 0.5  # hold after the jaws stop, before the motion


@dataclass
class GripReleaseConfig:
    opening_mm: float = 40.0
    speed_mm_s: float = 40.0


@dataclass
class GripDepthConfig:
    hardware: Any = MISSING
    skin: Any = MISSING
    sim: Any = None
    trajectory: TrajectoryConfig = field(default_factory=TrajectoryConfig)
    safety: SafetyConfig = field(default_factory=SafetyConfig)
    approach: GripApproachConfig = field(default_factory=GripApproachConfig)
    close: GripCloseConfig = field(default_factory=GripCloseConfig)
    release: GripReleaseConfig = field(default_factory=GripReleaseConfig)
    grip_depth: float = 12.0  # mm of commanded closure after contact
    trial: int = 0
    seed: int = 0
    data_root: str = "data"
    save_images: bool = False
    hold_s: float = 0.5  # pause before and after the motion
    control_period_s: float = 0.01
    trial_timeout_s: float = 300.0
    # The most skin frames the trial may lose and still be complete; 0 (default): none (see
    # ForceCalibrationConfig.max_lost_skin_frames).
    max_lost_skin_frames: int = 0
    progress: bool = True
    live: bool = False  # serve the run to Foxglove over WebSocket on 127.0.0.1:live_port
    live_port: int = 8765
    live_hold: bool = False  # with live: keep serving after the run until Ctrl-C
    # Where the live view listens (another address than loopback needs live_token); the host names
    # a client's Host and Origin headers may give (null: this machine and the Foxglove web app);
    # live_token: a client adding ?token=<it> to the URL is let in whatever it sends (a remote viewer)
    live_host: str = "127.0.0.1"
    live_allowed_hosts: list[str] | None = None
    live_token: str | None = None
    # An estimator artifact (the report's out/models/T-s5.pt): when set, every skin frame goes
    # through the online estimator and the session logs /estimate/force and /estimate/slip.
    estimator: str | None = None

    def __post_init__(self) -> None:
        s = self.safety
        require(self.estimator is None or Path(self.estimator).is_file(), "estimator", self.estimator,
                "must be an estimator artifact file (the report writes out/models/T-s5.pt), or null")
        require(0 < self.grip_depth <= s.max_grip_depth_mm, "grip_depth", self.grip_depth,
                f"must be > 0 mm and at most safety.max_grip_depth_mm={s.max_grip_depth_mm}")
        require(0 <= self.trial <= MAX_TRIAL, "trial", self.trial,
                f"must be a trial index in [0, {MAX_TRIAL}] (the study ran 7 per grip depth and motion)")
        a = self.approach
        stroke_mm = HARD["gripper_stroke_mm"]
        require(0 <= a.min_opening_mm < stroke_mm, "approach.min_opening_mm", a.min_opening_mm,
                f"must be in [0, {stroke_mm}) mm (the gripper's stroke)")
        require(a.min_opening_mm < a.start_opening_mm <= stroke_mm, "approach.start_opening_mm",
                a.start_opening_mm, f"must be in (approach.min_opening_mm={a.min_opening_mm}, {stroke_mm}] mm "
                "(the gripper's stroke)")
        require(a.min_opening_mm <= self.release.opening_mm <= stroke_mm, "release.opening_mm",
                self.release.opening_mm, f"must be in [approach.min_opening_mm={a.min_opening_mm}, {stroke_mm}] mm "
                "(the gripper's stroke)")
        reach_mm = a.start_opening_mm - a.min_opening_mm
        require(self.grip_depth <= reach_mm, "grip_depth", self.grip_depth,
                f"cannot be reached: even with contact at approach.start_opening_mm={a.start_opening_mm} the jaws "
                f"stop at approach.min_opening_mm={a.min_opening_mm} ({reach_mm:g} mm of closure at most)")
        _check_count("approach.threshold_counts", a.threshold_counts, 1, MAX_SKIN_SUM_COUNTS,
                     "counts summed over both layers; full scale is never exceeded")
        _check_count("approach.consecutive_frames", a.consecutive_frames, 1, MAX_CONSECUTIVE_FRAMES,
                     "the jaws close on while contact is confirmed")
        for key, value in (("approach.speed_mm_s", a.speed_mm_s), ("close.speed_mm_s", self.close.speed_mm_s),
                           ("release.speed_mm_s", self.release.speed_mm_s)):
            _check_speed(key, value, s.max_gripper_speed_mm_s, "safety.max_gripper_speed_mm_s")
        for key, value in (("approach.force_pct", a.force_pct), ("close.force_pct", self.close.force_pct)):
            require(0 <= value <= 100, key, value, "must be a percentage in [0, 100]")
        # Both motions are checked whichever runs: a sweep over the motion is refused as a whole.
        tr, to = self.trajectory.translation, self.trajectory.torsion
        _check_speed("trajectory.translation.speed_mm_s", tr.speed_mm_s, s.max_arm_speed_mm_s,
                     "safety.max_arm_speed_mm_s")
        require(max(abs(w) for w in tr.waypoints_mm) <= s.arm_max_offset_mm, "trajectory.translation.waypoints_mm",
                tr.waypoints_mm, f"must stay within safety.arm_max_offset_mm={s.arm_max_offset_mm}")
        _check_speed("trajectory.torsion.speed_deg_s", to.speed_deg_s, s.max_arm_angular_speed_deg_s,
                     "safety.max_arm_angular_speed_deg_s")
        require(max(abs(w) for w in to.waypoints_deg) <= s.arm_max_rotation_deg, "trajectory.torsion.waypoints_deg",
                to.waypoints_deg, f"must stay within safety.arm_max_rotation_deg={s.arm_max_rotation_deg}")
        # The arm driver refuses an acceleration above its own cap (sim.rig.arm / hardware.ur5e
        # max_accel_m_s2); UR's speedL reads the same argument as rad/s^2 for a torsion.
        cap_m_s2, cap_key = _arm_accel_cap(self)
        require(0 < tr.accel_mm_s2 <= 1000.0 * cap_m_s2, "trajectory.translation.accel_mm_s2", tr.accel_mm_s2,
                f"must be > 0 and at most the arm's {cap_key}={cap_m_s2} m/s^2 ({1000.0 * cap_m_s2:g} mm/s^2)")
        require(0 < to.accel_rad_s2 <= cap_m_s2, "trajectory.torsion.accel_rad_s2", to.accel_rad_s2,
                f"must be > 0 and at most {cap_m_s2} rad/s^2 (the arm's {cap_key}, which its driver applies to "
                "angular moves too)")
        require(CONTROL_PERIOD_S[0] <= self.control_period_s <= CONTROL_PERIOD_S[1], "control_period_s",
                self.control_period_s, f"must be in [{CONTROL_PERIOD_S[0]}, {CONTROL_PERIOD_S[1]}] s")
        require(TRIAL_TIMEOUT_S[0] <= self.trial_timeout_s <= TRIAL_TIMEOUT_S[1], "trial_timeout_s",
                self.trial_timeout_s, f"must be in [{TRIAL_TIMEOUT_S[0]}, {TRIAL_TIMEOUT_S[1]}] s")
        for key, value in (("hold_s", self.hold_s), ("close.settle_s", self.close.settle_s),
                           ("approach.baseline_s", a.baseline_s)):
            _check_duration(key, value, self.trial_timeout_s)
        # a config built in code may leave the skin unset ({}): the default readout's period then
        period_ms = getattr(self.skin, "frame_period_ms", None) or SkinConfig().frame_period_ms
        min_baseline_s = MIN_BASELINE_FRAMES * period_ms / 1000.0
        require(a.baseline_s >= min_baseline_s, "approach.baseline_s", a.baseline_s,
                f"must be >= {min_baseline_s:g} s ({MIN_BASELINE_FRAMES} skin frames of "
                f"skin.frame_period_ms={period_ms:g}): the baseline averages them, and with none it is "
                "0 counts and contact is detected at once")
        # the motion that runs fits in the trial (the other one may need a longer trial_timeout_s)
        if self.trajectory.motion == "translation":
            _check_motion_time("trajectory.translation.speed_mm_s", tr.speed_mm_s, tr.waypoints_mm, "mm",
                               self.trial_timeout_s)
        else:
            _check_motion_time("trajectory.torsion.speed_deg_s", to.speed_deg_s, to.waypoints_deg, "deg",
                               self.trial_timeout_s)
        require_seed("seed", self.seed)
        _check_lost_frames(self.max_lost_skin_frames)
        _check_live(self)
        _check_finite(self)
        _check_fault_devices(self.hardware, "gripper")
        _check_data_root(self.data_root)


def _store() -> None:
    cs = ConfigStore.instance()
    cs.store(name="force_calibration_schema", node=ForceCalibrationConfig)
    cs.store(name="grip_depth_schema", node=GripDepthConfig)
    cs.store(group="trajectory", name="trajectory_schema", node=TrajectoryConfig)


_store()
