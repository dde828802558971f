"""Analysis schemas (Hydra ConfigStore group `analysis`, and the root schemas of the `report` and
`design_map` apps).

Defaults are the study's settings; presets under conf/analysis/ (demo, default, paper) override
only what they change.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from hydra.core.config_store import ConfigStore

from layerskin_exp.config import SkinConfig, require
from layerskin_exp.estimation.config import (  # noqa: F401 - the analysis schema's groups
    CNN_CONFIGURATIONS,
    SLIP_CUES,
    CnnConfig,
    PreprocessConfig,
    SlipConfig,
)


@dataclass
class SplitConfig:
    train: float = 0.70
    val: float = 0.15
    test: float = 0.15
    seed: int = 0

    def __post_init__(self) -> None:
        ok = min(self.train, self.val, self.test) > 0 and abs(self.train + self.val + self.test - 1) < 1e-6
        require(ok, "analysis.split", (self.train, self.val, self.test),
                "train/val/test must be positive fractions summing to 1")


@dataclass
class CharacterizationConfig:
    matched_load_n: float = 2.0
    min_shared_load_n: float = 0.3
    shear_band_n: list[float] = field(default_factory=lambda: [1.9, 2.1])
    fz_bins_n: list[float] = field(default_factory=lambda: [0.5, 1.0, 2.0, 3.0, 4.0, 5.0, 6.5])
    min_fz_n: float = 0.5  # frames below this normal load are out of contact for the height fits
    n_bootstrap: int = 9999
    confidence: float = 0.95
    seed: int = 0

    def __post_init__(self) -> None:
        require(self.matched_load_n > 0, "analysis.characterization.matched_load_n", self.matched_load_n,
                "must be > 0 N")
        require(len(self.shear_band_n) == 2 and self.shear_band_n[0] < self.shear_band_n[1],
                "analysis.characterization.shear_band_n", self.shear_band_n, "needs [low, high] with low < high")
        e = self.fz_bins_n
        require(len(e) >= 2 and all(a < b for a, b in zip(e, e[1:], strict=False)),
                "analysis.characterization.fz_bins_n", e, "needs increasing bin edges")
        require(self.n_bootstrap >= 100, "analysis.characterization.n_bootstrap", self.n_bootstrap, "must be >= 100")
        require(0 < self.confidence < 1, "analysis.characterization.confidence", self.confidence, "must be in (0, 1)")


@dataclass
class AnalysisConfig:
    preprocess: PreprocessConfig = field(default_factory=PreprocessConfig)
    split: SplitConfig = field(default_factory=SplitConfig)
    cnn: CnnConfig = field(default_factory=CnnConfig)
    characterization: CharacterizationConfig = field(default_factory=CharacterizationConfig)
    slip: SlipConfig = field(default_factory=SlipConfig)
    figures: bool = True
    progress: bool = True


@dataclass
class ReportConfig:
    sessions: str = "data"  # the protocols' data_root: a run's sessions are reported without sessions=
    out: str = "outputs/report"
    # A sensitivity screening result (`python -m protocols.sensitivity out=FILE`): the characterisation
    # section shows its bands over the simulator's brackets beside the study. None: no bands.
    sensitivity: str | None = None
    skin: SkinConfig = field(default_factory=SkinConfig)
    analysis: AnalysisConfig = field(default_factory=AnalysisConfig)

    def __post_init__(self) -> None:
        if self.sensitivity is not None:  # read before any analysis runs: a bad file ends the run up front
            from analysis.sensitivity_result import load_result

            load_result(self.sensitivity)


@dataclass
class DesignMapConfig:
    sweep_dir: str = "data/design_sweep"
    out: str | None = None  # default <sweep_dir>/design_map
    fz_bins_n: list[float] = field(default_factory=lambda: [1.0, 2.5, 4.0, 6.5])
    sensitivity_max_shear_n: float = 1.0
    saturation_ratio: float = 0.3
    noise_sigmas: float = 2.0
    min_frames: int = 30
    folds: int = 4  # position-grouped folds of every estimator's R²
    ts5: bool = True  # train the T-s5 CNN-GRU per design and fold
    n_jobs: int = 1  # campaigns measured in parallel (processes; each trains on one torch thread)
    figures: bool = True
    progress: bool = False
    # The sweep's T-s5 preset: the demo's optimiser (batch 64, lr 1e-3 halved on plateaus, 4096
    # windows an epoch) capped at 12 epochs (768 steps, ~28 CPU-s a fold on this machine). The
    # report needs ~3000 steps to pass the linear baseline on Fx (conf/analysis/default.yaml), so
    # the map's T-s5 is a short-budget model: compare designs by it, not against the study.
    cnn: CnnConfig = field(default_factory=lambda: CnnConfig(
        configurations=["T-s5"], batch_size=64, segment_windows=16, lr=1e-3, lr_schedule="plateau",
        lr_plateau_factor=0.5, lr_plateau_patience=2, max_epochs=12, patience=4, max_train_windows=4096,
        torch_threads=1))
    preprocess: PreprocessConfig = field(default_factory=PreprocessConfig)
    characterization: CharacterizationConfig = field(default_factory=lambda: CharacterizationConfig(n_bootstrap=999))


def _store() -> None:
    cs = ConfigStore.instance()
    cs.store(group="analysis", name="analysis_schema", node=AnalysisConfig)
    cs.store(name="report_schema", node=ReportConfig)
    cs.store(name="design_map_schema", node=DesignMapConfig)


_store()
