"""Hyperparameters of the estimators (plain dataclasses; the report's Hydra schema reuses them).

Defaults are the study's settings. Field errors name the key under `analysis.` where the report
exposes them.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from layerskin_exp.config import require

CNN_CONFIGURATIONS = ("T-s1", "T-s5", "S-s1", "S-s5", "D-s1", "D-s5")
SLIP_CUES = ("interlayer", "superficial", "geometric", "f_xyz", "f_z")


@dataclass
class PreprocessConfig:
    ma_window: int = 5  # moving average, samples
    downsample: int = 5  # block mean, samples
    baseline_frames: int = 20  # raw frames at trial start whose median is the per-taxel baseline
    scale_percentile: float = 99.0  # per-layer scale: this percentile of frame totals -> 1
    eps: float = 1e-3  # CoP denominator guard, in normalised total units

    def __post_init__(self) -> None:
        require(self.ma_window >= 1 and self.ma_window % 2 == 1, "analysis.preprocess.ma_window",
                self.ma_window, "must be an odd number of samples >= 1")
        require(self.downsample >= 1, "analysis.preprocess.downsample", self.downsample, "must be >= 1")
        require(self.baseline_frames >= 1, "analysis.preprocess.baseline_frames", self.baseline_frames,
                "must be >= 1")
        require(0 < self.scale_percentile <= 100, "analysis.preprocess.scale_percentile",
                self.scale_percentile, "must be in (0, 100]")
        require(self.eps > 0, "analysis.preprocess.eps", self.eps, "must be > 0")


@dataclass
class CnnConfig:
    configurations: list[str] = field(default_factory=lambda: list(CNN_CONFIGURATIONS))
    max_epochs: int = 200
    patience: int = 20  # epochs without validation improvement before stopping
    batch_size: int = 256
    lr: float = 3e-4
    # "constant" (the study's Adam at lr) or "plateau": lr times lr_plateau_factor whenever the
    # validation loss has not improved for lr_plateau_patience epochs (torch ReduceLROnPlateau).
    lr_schedule: str = "constant"
    lr_plateau_factor: float = 0.5
    lr_plateau_patience: int = 2
    dropout: float = 0.1
    axis_weights: list[float] = field(default_factory=lambda: [1.0, 1.0, 1.0])  # Fx, Fy, Fz loss weights
    smooth_l1_beta: float = 1.0
    segment_windows: int = 64  # windows per contiguous segment in a batch (frames encoded once)
    max_train_windows: int | None = None  # per-epoch subsample of training windows (demo)
    device: str = "auto"  # auto | cpu | cuda
    torch_threads: int | None = None  # None: default_torch_threads (1), set by the report for its run
    seed: int = 0

    def __post_init__(self) -> None:
        for c in self.configurations:
            require(c in CNN_CONFIGURATIONS, "analysis.cnn.configurations", c,
                    f"must be one of {', '.join(CNN_CONFIGURATIONS)}")
        require(self.max_epochs >= 1, "analysis.cnn.max_epochs", self.max_epochs, "must be >= 1")
        require(self.patience >= 1, "analysis.cnn.patience", self.patience, "must be >= 1")
        require(self.batch_size >= 1, "analysis.cnn.batch_size", self.batch_size, "must be >= 1")
        require(self.lr > 0, "analysis.cnn.lr", self.lr, "must be > 0")
        require(self.lr_schedule in ("constant", "plateau"), "analysis.cnn.lr_schedule", self.lr_schedule,
                "must be constant or plateau")
        require(0 < self.lr_plateau_factor < 1, "analysis.cnn.lr_plateau_factor", self.lr_plateau_factor,
                "must be in (0, 1)")
        require(self.lr_plateau_patience >= 0, "analysis.cnn.lr_plateau_patience", self.lr_plateau_patience,
                "must be >= 0 epochs")
        require(0 <= self.dropout < 1, "analysis.cnn.dropout", self.dropout, "must be in [0, 1)")
        require(len(self.axis_weights) == 3 and min(self.axis_weights) >= 0, "analysis.cnn.axis_weights",
                self.axis_weights, "needs three non-negative weights (Fx, Fy, Fz)")
        require(self.segment_windows >= 1, "analysis.cnn.segment_windows", self.segment_windows, "must be >= 1")
        require(self.device in ("auto", "cpu", "cuda"), "analysis.cnn.device", self.device,
                "must be auto, cpu or cuda")
        require(self.torch_threads is None or self.torch_threads >= 1, "analysis.cnn.torch_threads",
                self.torch_threads, "must be >= 1 or null (the default, one thread)")


@dataclass
class SlipConfig:
    truth_lowpass_hz: float = 8.0
    truth_order: int = 4
    truth_mad_k: float = 1.4826
    truth_min_interval_s: float = 0.150
    vision_rate_hz: float = 30.0  # vision signals are resampled onto a uniform grid at this rate
    band_hz: list[float] = field(default_factory=lambda: [0.3, 12.0])
    band_order: int = 2
    envelope_s: float = 0.060
    tolerance_s: float = 0.100
    offset_min_s: float = -0.20  # latency offsets tried (added to tactile event times)
    offset_max_s: float = 0.20
    offset_step_s: float = 0.01
    n_thresholds: int = 40
    cues: list[str] = field(default_factory=lambda: list(SLIP_CUES))

    def __post_init__(self) -> None:
        require(self.truth_lowpass_hz > 0, "analysis.slip.truth_lowpass_hz", self.truth_lowpass_hz, "must be > 0")
        require(len(self.band_hz) == 2 and 0 < self.band_hz[0] < self.band_hz[1], "analysis.slip.band_hz",
                self.band_hz, "needs [low, high] in Hz with 0 < low < high")
        require(self.tolerance_s > 0, "analysis.slip.tolerance_s", self.tolerance_s, "must be > 0")
        require(self.offset_step_s > 0 and self.offset_min_s <= self.offset_max_s, "analysis.slip.offset_step_s",
                self.offset_step_s, "needs step > 0 and offset_min_s <= offset_max_s")
        require(self.n_thresholds >= 2, "analysis.slip.n_thresholds", self.n_thresholds, "must be >= 2")
        for c in self.cues:
            require(c in SLIP_CUES, "analysis.slip.cues", c, f"must be one of {', '.join(SLIP_CUES)}")
