"""Parameters of the simulated rig's devices and world (clocks, F/T, platform, arm, gripper, camera).

Every value is physical and named with its unit; `__post_init__` range-checks it and raises a
ConfigError naming the key. `SimConfig` (layerskin_exp/sim/config.py) holds one `rig: RigConfig`.
Defaults come from the devices' datasheets where one exists (Mini40 SI-20-1 resolution, UR5e RTDE
rate, Hand-E stroke and speeds, D435 colour intrinsics at 640x480); the rest are stated guesses.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from datetime import datetime, timezone

from layerskin_exp.config import require
from layerskin_exp.vision.camera_model import CameraModelConfig


@dataclass
class DeviceClockConfig:
    """One device's own clock and its link to the host.

    device time = offset + (1 + drift) * true time + timestamp jitter; the offset is drawn
    uniformly in [0, offset_max_s], the drift from N(0, drift_ppm_std). Host receive time =
    host time of the sample + delay_min_ms + Exp(delay_mean_extra_ms), kept first-in first-out.
    """

    offset_max_s: float = 1000.0
    drift_ppm_std: float = 30.0
    timestamp_jitter_us: float = 5.0
    delay_min_ms: float = 0.5
    delay_mean_extra_ms: float = 0.3

    def check(self, key: str) -> None:
        require(self.offset_max_s >= 0, f"{key}.offset_max_s", self.offset_max_s, "must be >= 0 s")
        require(0 <= self.drift_ppm_std <= 1000, f"{key}.drift_ppm_std", self.drift_ppm_std,
                "must be 0..1000 ppm (quartz clocks drift tens of ppm)")
        require(self.timestamp_jitter_us >= 0, f"{key}.timestamp_jitter_us", self.timestamp_jitter_us,
                "must be >= 0 us")
        require(self.delay_min_ms >= 0, f"{key}.delay_min_ms", self.delay_min_ms, "must be >= 0 ms")
        require(self.delay_mean_extra_ms >= 0, f"{key}.delay_mean_extra_ms", self.delay_mean_extra_ms,
                "must be >= 0 ms")

    def __post_init__(self) -> None:
        self.check("clock")


@dataclass
class SkinReaderConfig:
    """The readout board's stream: frame pairs every skin.frame_period_ms on average."""

    period_jitter_ms: float = 0.08  # scan-to-scan spread of the frame period (std)
    clock: DeviceClockConfig = field(default_factory=lambda: DeviceClockConfig(
        drift_ppm_std=40.0, timestamp_jitter_us=2.0, delay_min_ms=0.4, delay_mean_extra_ms=0.3))
    board_id: str = "sim-fsr2x16"

    def __post_init__(self) -> None:
        require(0 <= self.period_jitter_ms < 1.0, "sim.rig.skin.period_jitter_ms", self.period_jitter_ms,
                "must be 0..1 ms")
        self.clock.check("sim.rig.skin.clock")


@dataclass
class ForceTorqueConfig:
    """ATI Mini40 (SI-20-1) under the skin, streamed over Net F/T RDT."""

    rate_hz: float = 1000.0
    # Datasheet resolution, used as the noise std: Fx, Fy 1/200 N, Fz 1/100 N, torques 1/8000 N·m.
    force_noise_n: tuple[float, float, float] = (0.005, 0.005, 0.01)
    torque_noise_nm: tuple[float, float, float] = (1.25e-4, 1.25e-4, 1.25e-4)
    bias_force_max_n: float = 0.3  # untared bias, uniform in +-, per axis
    bias_torque_max_nm: float = 0.005
    bias_drift_n_per_s: float = 0.0005  # slow thermal drift, random-walk std per sqrt(s)
    sensor_depth_mm: float = 8.0  # sensor origin below the skin surface (lever arm for torques)
    clock: DeviceClockConfig = field(default_factory=lambda: DeviceClockConfig(
        drift_ppm_std=25.0, timestamp_jitter_us=1.0, delay_min_ms=0.2, delay_mean_extra_ms=0.1))

    def __post_init__(self) -> None:
        k = "sim.rig.ft"
        require(10 <= self.rate_hz <= 7000, f"{k}.rate_hz", self.rate_hz, "Net F/T streams 10..7000 Hz")
        require(len(self.force_noise_n) == 3 and min(self.force_noise_n) >= 0, f"{k}.force_noise_n",
                self.force_noise_n, "three non-negative stds in N")
        require(len(self.torque_noise_nm) == 3 and min(self.torque_noise_nm) >= 0, f"{k}.torque_noise_nm",
                self.torque_noise_nm, "three non-negative stds in N·m")
        require(self.bias_force_max_n >= 0, f"{k}.bias_force_max_n", self.bias_force_max_n, "must be >= 0")
        require(self.bias_torque_max_nm >= 0, f"{k}.bias_torque_max_nm", self.bias_torque_max_nm, "must be >= 0")
        require(self.bias_drift_n_per_s >= 0, f"{k}.bias_drift_n_per_s", self.bias_drift_n_per_s, "must be >= 0")
        require(self.sensor_depth_mm >= 0, f"{k}.sensor_depth_mm", self.sensor_depth_mm, "must be >= 0")
        self.clock.check(f"{k}.clock")


@dataclass
class PlatformConfig:
    """Three-axis linear platform carrying the hemispherical indenter; skin frame, mm."""

    workspace_min_mm: tuple[float, float, float] = (-15.0, -15.0, -4.0)
    workspace_max_mm: tuple[float, float, float] = (15.0, 15.0, 30.0)
    max_speed_mm_s: float = 20.0
    max_accel_mm_s2: float = 200.0
    home_mm: tuple[float, float, float] = (0.0, 0.0, 5.0)
    rate_hz: float = 200.0  # position stream
    encoder_resolution_mm: float = 0.001
    clock: DeviceClockConfig = field(default_factory=lambda: DeviceClockConfig(
        drift_ppm_std=50.0, timestamp_jitter_us=20.0, delay_min_ms=1.0, delay_mean_extra_ms=0.5))

    def __post_init__(self) -> None:
        k = "sim.rig.platform"
        require(len(self.workspace_min_mm) == 3 and len(self.workspace_max_mm) == 3
                and all(a < b for a, b in zip(self.workspace_min_mm, self.workspace_max_mm, strict=True)),
                f"{k}.workspace_min_mm", self.workspace_min_mm, "three bounds, each below workspace_max_mm")
        require(all(a <= h <= b for a, h, b in zip(self.workspace_min_mm, self.home_mm,
                                                   self.workspace_max_mm, strict=True)),
                f"{k}.home_mm", self.home_mm, "must lie inside the workspace")
        require(0 < self.max_speed_mm_s <= 500, f"{k}.max_speed_mm_s", self.max_speed_mm_s, "must be 0..500")
        require(0 < self.max_accel_mm_s2 <= 1e4, f"{k}.max_accel_mm_s2", self.max_accel_mm_s2, "must be 0..1e4")
        require(1 <= self.rate_hz <= 2000, f"{k}.rate_hz", self.rate_hz, "must be 1..2000 Hz")
        require(self.encoder_resolution_mm >= 0, f"{k}.encoder_resolution_mm", self.encoder_resolution_mm,
                "must be >= 0")
        self.clock.check(f"{k}.clock")


@dataclass
class ArmConfig:
    """UR5e TCP, driven by linear tool moves, streamed over RTDE at 500 Hz."""

    rate_hz: float = 500.0
    max_speed_m_s: float = 0.25  # a conservative cap on top of the UR's own 1 m/s
    max_accel_m_s2: float = 1.5
    max_angular_speed_rad_s: float = 1.0
    max_angular_accel_rad_s2: float = 3.0
    # Reachable box for the TCP (m), base frame; commands outside raise.
    workspace_min_m: tuple[float, float, float] = (-0.6, -0.6, 0.05)
    workspace_max_m: tuple[float, float, float] = (0.6, 0.6, 0.8)
    home_pose6: tuple[float, float, float, float, float, float] = (0.3, -0.2, 0.25, 3.1416, 0.0, 0.0)
    position_noise_m: float = 2e-6  # joint encoders -> TCP
    clock: DeviceClockConfig = field(default_factory=lambda: DeviceClockConfig(
        drift_ppm_std=20.0, timestamp_jitter_us=10.0, delay_min_ms=0.3, delay_mean_extra_ms=0.3))

    def __post_init__(self) -> None:
        k = "sim.rig.arm"
        require(1 <= self.rate_hz <= 500, f"{k}.rate_hz", self.rate_hz, "RTDE streams up to 500 Hz")
        require(0 < self.max_speed_m_s <= 1.0, f"{k}.max_speed_m_s", self.max_speed_m_s, "must be 0..1 m/s")
        require(0 < self.max_accel_m_s2 <= 15, f"{k}.max_accel_m_s2", self.max_accel_m_s2, "must be 0..15")
        require(0 < self.max_angular_speed_rad_s <= 3.2, f"{k}.max_angular_speed_rad_s",
                self.max_angular_speed_rad_s, "must be 0..3.2 rad/s")
        require(0 < self.max_angular_accel_rad_s2 <= 40, f"{k}.max_angular_accel_rad_s2",
                self.max_angular_accel_rad_s2, "must be 0..40")
        require(all(a < b for a, b in zip(self.workspace_min_m, self.workspace_max_m, strict=True)),
                f"{k}.workspace_min_m", self.workspace_min_m, "each bound below workspace_max_m")
        require(len(self.home_pose6) == 6 and all(
            a <= h <= b for a, h, b in zip(self.workspace_min_m, self.home_pose6[:3], self.workspace_max_m,
                                           strict=True)),
                f"{k}.home_pose6", self.home_pose6, "six values, position inside the workspace")
        require(self.position_noise_m >= 0, f"{k}.position_noise_m", self.position_noise_m, "must be >= 0")
        self.clock.check(f"{k}.clock")


@dataclass
class GripperConfig:
    """Robotiq Hand-E with the skin on one finger, and the fixed rod it presses (rig.ROD_DIAMETER_MM).

    The jaws are symmetric: closing the opening by d moves each finger d/2. The skin finger's
    cover meets the rod at `contact_opening_mm`; past that, the commanded finger travel presses
    the rod into the skin through the series compliance (skin model's support stiffness).
    """

    stroke_mm: float = 50.0
    min_speed_mm_s: float = 20.0
    max_speed_mm_s: float = 150.0
    accel_mm_s2: float = 1000.0
    force_min_n: float = 20.0  # grip force at force_pct 0 (datasheet 20..185 N)
    force_max_n: float = 185.0
    rate_hz: float = 100.0  # state polling
    position_resolution_mm: float = 50.0 / 255.0  # 8-bit register
    initial_opening_mm: float = 50.0
    contact_opening_mm: float = 36.0  # opening at which the skin cover touches the rod
    other_finger_clearance_mm: float = 30.0  # other finger's gap to the rod at contact (it never touches)
    # Lumped series compliance of the printed finger adapter carrying the skin and the rod's stand.
    # An assumption (not measured); null = rigid, which lets the Hand-E crush the skin up to its
    # 20 N minimum grip force.
    support_stiffness_n_per_mm: float | None = 1.0
    clock: DeviceClockConfig = field(default_factory=lambda: DeviceClockConfig(
        drift_ppm_std=50.0, timestamp_jitter_us=50.0, delay_min_ms=2.0, delay_mean_extra_ms=2.0))

    def __post_init__(self) -> None:
        k = "sim.rig.gripper"
        require(self.stroke_mm > 0, f"{k}.stroke_mm", self.stroke_mm, "must be > 0")
        require(0 < self.min_speed_mm_s <= self.max_speed_mm_s, f"{k}.min_speed_mm_s", self.min_speed_mm_s,
                "must be > 0 and <= max_speed_mm_s")
        require(self.accel_mm_s2 > 0, f"{k}.accel_mm_s2", self.accel_mm_s2, "must be > 0")
        require(0 < self.force_min_n <= self.force_max_n, f"{k}.force_min_n", self.force_min_n,
                "must be > 0 and <= force_max_n")
        require(1 <= self.rate_hz <= 1000, f"{k}.rate_hz", self.rate_hz, "must be 1..1000 Hz")
        require(0 <= self.initial_opening_mm <= self.stroke_mm, f"{k}.initial_opening_mm",
                self.initial_opening_mm, "must lie in the stroke")
        require(0 < self.contact_opening_mm < self.stroke_mm, f"{k}.contact_opening_mm",
                self.contact_opening_mm, "must lie inside the stroke")
        require(self.other_finger_clearance_mm >= 0, f"{k}.other_finger_clearance_mm",
                self.other_finger_clearance_mm, "must be >= 0")
        require(self.support_stiffness_n_per_mm is None or self.support_stiffness_n_per_mm > 0,
                f"{k}.support_stiffness_n_per_mm", self.support_stiffness_n_per_mm, "must be > 0 or null")
        self.clock.check(f"{k}.clock")


@dataclass
class CameraConfig(CameraModelConfig):
    """Fixed RealSense D435 colour stream looking at the two ArUco markers on the superficial layer
    (image size, intrinsics and distance: CameraModelConfig; the markers: the rig's)."""

    KEY = "sim.rig.camera"

    fps: float = 30.0
    supersample: int = 4  # render at 4x and average down: edges placed to ~0.005 px (2x: ~0.015 px, ~0.4 deg of tilt)
    blur_sigma_px: float = 0.6
    noise_std_gray: float = 2.0
    latency_ms: float = 75.0
    latency_jitter_ms: float = 3.0
    keep_images: bool = False
    clock: DeviceClockConfig = field(default_factory=lambda: DeviceClockConfig(
        drift_ppm_std=30.0, timestamp_jitter_us=100.0, delay_min_ms=0.0, delay_mean_extra_ms=0.0))

    def __post_init__(self) -> None:
        k = self.KEY
        require(0 < self.fps <= 120, f"{k}.fps", self.fps, "must be 0..120")
        self.check_model()
        require(1 <= self.supersample <= 8, f"{k}.supersample", self.supersample, "must be 1..8")
        require(self.blur_sigma_px >= 0, f"{k}.blur_sigma_px", self.blur_sigma_px, "must be >= 0")
        require(self.noise_std_gray >= 0, f"{k}.noise_std_gray", self.noise_std_gray, "must be >= 0")
        require(0 <= self.latency_ms < 1000, f"{k}.latency_ms", self.latency_ms, "must be 0..1000 ms")
        require(self.latency_jitter_ms >= 0, f"{k}.latency_jitter_ms", self.latency_jitter_ms, "must be >= 0")
        self.clock.check(f"{k}.clock")


@dataclass
class TrialVariationConfig:
    """What differs from one trial to the next on a real bench, drawn per trial.

    Each trial's draw (and its sensor noise, clock jitter and link delays) follows from the world
    seed and the trial's labels, so repeated trials are distinct realisations and any trial replays
    identically however the campaign ran. The sensor itself (taxel gains, baselines, device clock
    offsets and drifts) is fixed by the seed: the same skin is used throughout.
    Stated guesses, not measurements: set them to 0 for identical repeats.
    """

    friction_cv: float = 0.05  # relative spread of the cover's friction (surface state, dust, humidity)
    rod_offset_sd_mm: float = 0.3  # where the rod sits across the skin (re-clamped between grip trials)
    rod_yaw_sd_deg: float = 1.0  # the rod's angle on the skin

    def __post_init__(self) -> None:
        k = "sim.rig.variation"
        require(0 <= self.friction_cv < 0.5, f"{k}.friction_cv", self.friction_cv, "must be 0..0.5")
        require(0 <= self.rod_offset_sd_mm <= 3, f"{k}.rod_offset_sd_mm", self.rod_offset_sd_mm, "must be 0..3 mm")
        require(0 <= self.rod_yaw_sd_deg <= 10, f"{k}.rod_yaw_sd_deg", self.rod_yaw_sd_deg, "must be 0..10 deg")


@dataclass
class RigConfig:
    """The simulated rig: world stepping plus every device's twin."""

    mech_rate_hz: float = 1000.0  # skin mechanics step rate
    host_start_s: float = 100.0  # virtual host monotonic clock at world start
    # When the simulated run starts, in UTC (e.g. "2026-01-05T09:00:00Z"); null: the wall clock
    # when the run starts. Files are byte-identical across reruns only with a fixed start.
    start_time: str | None = None
    skin: SkinReaderConfig = field(default_factory=SkinReaderConfig)
    ft: ForceTorqueConfig = field(default_factory=ForceTorqueConfig)
    platform: PlatformConfig = field(default_factory=PlatformConfig)
    arm: ArmConfig = field(default_factory=ArmConfig)
    gripper: GripperConfig = field(default_factory=GripperConfig)
    camera: CameraConfig = field(default_factory=CameraConfig)
    variation: TrialVariationConfig = field(default_factory=TrialVariationConfig)

    def __post_init__(self) -> None:
        require(100 <= self.mech_rate_hz <= 10000, "sim.rig.mech_rate_hz", self.mech_rate_hz,
                "must be 100..10000 Hz")
        require(self.host_start_s >= 0, "sim.rig.host_start_s", self.host_start_s, "must be >= 0")
        if self.start_time is not None:
            start_time_ns(self.start_time)

    def run_start_ns(self) -> int:
        """Unix ns at which this run's simulated clock starts (start_time, else now)."""
        return time.time_ns() if self.start_time is None else start_time_ns(self.start_time)


START_YEARS = (1970, 2200)


def start_time_ns(text) -> int:
    """Unix ns of a UTC date and time in ISO 8601 ("2026-01-05T09:00:00Z"); ConfigError otherwise."""
    what = ("must be a UTC date and time like 2026-01-05T09:00:00Z (or null for the wall clock when the run "
            "starts)")
    try:
        when = datetime.fromisoformat(str(text).replace("Z", "+00:00")) if isinstance(text, str) else None
    except ValueError:
        when = None
    require(when is not None and when.utcoffset() is not None, "sim.rig.start_time", text, what)
    require(START_YEARS[0] <= when.astimezone(timezone.utc).year < START_YEARS[1], "sim.rig.start_time", text,
            f"must lie in the years {START_YEARS[0]}..{START_YEARS[1] - 1}")
    delta = when - datetime(1970, 1, 1, tzinfo=timezone.utc)
    return (delta.days * 86_400 + delta.seconds) * 1_000_000_000 + delta.microseconds * 1_000
