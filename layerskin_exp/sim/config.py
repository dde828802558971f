"""Parameters of the simulated skin: spacer, cover, contact, FSR transduction, readout.

Every default is a material datum or a geometric fact of the study's sensor, never a value
fitted to the study's results. Each section checks its own ranges in `__post_init__` and raises
a `ConfigError` naming the key (`sim.spacer.modulus_kpa=-3.0: ...`). `SimConfig` is stored in
Hydra's ConfigStore as `sim/sim_schema`; `conf/sim/default.yaml` fills it in, so a design sweep
is `-m sim.spacer.modulus_kpa=20,35,60`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hydra.core.config_store import ConfigStore
from omegaconf import MISSING

from layerskin_exp.config import require, require_seed, retire
from layerskin_exp.sim.rig_config import RigConfig
from layerskin_exp.sim.spacer_config import SpacerConfig
from layerskin_exp.sim.spacer_config import positive as _positive

# The bracket or source of each outcome-moving parameter of the simulated bench, read by the
# sensitivity screen and the design map. Kept out of conf/sim/: it is no `sim=` choice.
BRACKETS_FILE = Path(__file__).resolve().with_name("brackets.yaml")


def load_brackets(path=BRACKETS_FILE) -> dict[str, dict]:
    """{override key: entry} of a brackets file (the one reader of it: the screen, the design map).

    Each entry has its `nominal` value and a `source`, and either `levels` (a switch) holding the
    nominal or a bracket `low` <= nominal <= `high`; ConfigError names the first entry that has not."""
    from omegaconf import OmegaConf

    doc = OmegaConf.to_container(OmegaConf.load(path))
    entries = doc.get("parameters") if isinstance(doc, dict) else None
    require(isinstance(entries, dict) and entries, "brackets", str(path), "needs a `parameters:` mapping of entries")
    for key, e in entries.items():
        ok = isinstance(e, dict) and "nominal" in e and bool(e.get("source"))
        if ok and "levels" in e:
            ok = e["nominal"] in e["levels"]
        elif ok:
            ok = all(isinstance(e.get(k), int | float) for k in ("low", "high", "nominal")) and (
                e["low"] <= e["nominal"] <= e["high"])
        require(ok, f"brackets {path}: {key}", e, "needs nominal, source, and levels holding the nominal or "
                "low <= nominal <= high")
    return dict(entries)


def _fraction(value: float, key: str, lo_open: bool = False) -> None:
    ok = value is not None and (0 < value < 1 if lo_open else 0 <= value < 1)
    require(ok, key, value, "must lie in (0, 1)" if lo_open else "must lie in [0, 1)")


@dataclass
class CoverConfig:
    """The 0.2 mm silicone cover on the contact side and its friction with the indenter.

    Soft silicone on printed plastic has a static coefficient near 1 (0.8-1.5 is typical);
    kinetic friction is lower. `aging_s`: time for the static coefficient to recover after a
    slip (contact ageing); `overshoot`: how far a slip runs past the kinetic level, from an
    undamped (1) to a critically damped (0) slip of the superficial layer.
    """

    thickness_mm: float = 0.2
    modulus_kpa: float = 35.0  # Young's modulus of the cover silicone
    friction: float = 1.0  # static coefficient
    kinetic_ratio: float = 0.75  # kinetic / static
    aging_s: float = 0.05
    overshoot: float = 0.5

    def __post_init__(self) -> None:
        _positive(self.thickness_mm, "sim.cover.thickness_mm", "cover thickness must be > 0 mm")
        _positive(self.modulus_kpa, "sim.cover.modulus_kpa", "cover Young's modulus must be > 0 kPa")
        _positive(self.friction, "sim.cover.friction", "static friction coefficient must be > 0")
        require(self.kinetic_ratio is not None and 0 < self.kinetic_ratio <= 1, "sim.cover.kinetic_ratio",
                self.kinetic_ratio, "kinetic/static ratio must lie in (0, 1]")
        require(self.aging_s is not None and self.aging_s >= 0, "sim.cover.aging_s", self.aging_s, "must be >= 0 s")
        require(self.overshoot is not None and 0 <= self.overshoot <= 1, "sim.cover.overshoot", self.overshoot,
                "must lie in [0, 1]")

    @property
    def kinetic(self) -> float:
        return self.friction * self.kinetic_ratio


@dataclass
class SheetConfig:
    """How one FSR sheet is built: two electrode films (polyimide with copper strips, the strips
    of the two films crossed) laminated around the Velostat. Sets the superficial sheet's
    bending rigidity, which spreads the indenter's load over the lattice (`laminate`).

    `interface`: how the films hold to the Velostat. They must touch it to conduct, so over the
    active area nothing but friction holds them (lamination seals the rim): "friction" (default)
    lets each film stick where friction mu p can carry the sandwich's shear flow and slip where
    it cannot (`laminate.FrictionInterface`). The bounds: "bonded" (a glued sandwich, D = 5.7 N mm
    with the defaults) and "unbonded" (the films and core bend on their own, 0.11 N mm).
    `interface_friction`: the film-Velostat friction coefficient.
    `large_deflection`: the hemisphere's sheet also stretches as it sinks (a von Karman plate with
    the films' membrane stiffness, `laminate`), which the 3D model of the study's geometry shows
    carrying most of a 3 N press outwards (docs/simulator-validation.md says what it does to each
    row); where a profile reaches past the pad's sides the frame pipeline adds that load back as the
    sheet's rigid-body pressure (frame_kernels._pad_fold). Off: a bending plate only.
    `wrinkling` (with `large_deflection`): the stretched sheet wrinkles where its membrane would be
    compressed past 2 sqrt(D k) (a plate on a Winkler foundation, Hetenyi), and carries no more
    compression than that there (a tension-field membrane, `laminate._tension_field`). Off: the
    smooth sheet, as the 3D model's, which keeps any hoop compression: its rim, 20 times past that
    load, spreads a 3 N press over the whole pad and takes most of the inter-layer count shift out of
    the skin."""

    film_modulus_mpa: float = 2500.0  # polyimide
    film_thickness_mm: float = 0.025
    copper_modulus_mpa: float = 117000.0
    copper_thickness_mm: float = 0.018
    electrode_fill: float = 0.8  # 1.2 mm electrodes at 1.5 mm pitch
    velostat_modulus_mpa: float = 150.0
    velostat_thickness_mm: float = 0.1
    interface: str = "friction"  # friction | bonded | unbonded
    interface_friction: float = 0.3  # copper / polyimide on carbon-loaded polyolefin
    large_deflection: bool = True  # the sheet's membrane action (von Karman), hemisphere only
    wrinkling: bool = True  # with large_deflection: the sheet wrinkles past 2 sqrt(D k) of compression

    def __post_init__(self) -> None:
        for key in ("film_modulus_mpa", "film_thickness_mm", "copper_modulus_mpa", "copper_thickness_mm",
                    "velostat_modulus_mpa", "velostat_thickness_mm"):
            _positive(getattr(self, key), f"sim.sheet.{key}")
        require(self.electrode_fill is not None and 0 < self.electrode_fill <= 1, "sim.sheet.electrode_fill",
                self.electrode_fill, "must lie in (0, 1]")
        require(self.interface in ("friction", "bonded", "unbonded"), "sim.sheet.interface", self.interface,
                "must be 'friction', 'bonded' or 'unbonded'")
        require(self.interface_friction is not None and self.interface_friction >= 0, "sim.sheet.interface_friction",
                self.interface_friction, "must be >= 0")
        require(isinstance(self.large_deflection, bool), "sim.sheet.large_deflection", self.large_deflection,
                "must be true or false")
        require(isinstance(self.wrinkling, bool), "sim.sheet.wrinkling", self.wrinkling, "must be true or false")

    def _rigidity(self, bonded: bool) -> float:
        from layerskin_exp.sim.laminate import sheet_rigidity_n_mm

        return sheet_rigidity_n_mm(self.film_modulus_mpa, self.film_thickness_mm, self.copper_modulus_mpa,
                                   self.copper_thickness_mm, self.electrode_fill, self.velostat_thickness_mm,
                                   self.velostat_modulus_mpa, bonded)

    @property
    def rigidity_n_mm(self) -> float:
        """Bending rigidity D of the sheet (N mm) where its films slip (friction, unbonded) or
        stick (bonded); see laminate.sheet_rigidity_n_mm."""
        return self._rigidity(self.interface == "bonded")

    @property
    def membrane_n_per_mm(self) -> float:
        """The sheet's membrane stiffness in its plane (N/mm); see laminate.sheet_membrane_n_per_mm."""
        from layerskin_exp.sim.laminate import sheet_membrane_n_per_mm

        return sheet_membrane_n_per_mm(self.film_modulus_mpa, self.film_thickness_mm, self.copper_modulus_mpa,
                                       self.copper_thickness_mm, self.electrode_fill, self.velostat_thickness_mm,
                                       self.velostat_modulus_mpa)

    @property
    def sandwich_rigidity_n_mm(self) -> float:
        """D of the fully bonded sandwich (what sticking films give)."""
        return self._rigidity(True)

    @property
    def film_separation_mm(self) -> float:
        """Distance between the two electrode films' mid-planes (the sandwich's lever arm)."""
        return self.velostat_thickness_mm + self.film_thickness_mm + self.copper_thickness_mm


@dataclass
class ContactConfig:
    """The numerical resolution of the contact model (the indenter and the rod are the rig's:
    `layerskin_exp.rig.INDENTER_RADIUS_MM`, `ROD_DIAMETER_MM`)."""

    quad_points: int = 3  # Gauss points per axis over each taxel electrode
    table_points: int = 96  # indentation samples in the precomputed contact tables

    def __post_init__(self) -> None:
        require(self.quad_points in (1, 2, 3, 4), "sim.contact.quad_points", self.quad_points, "must be 1..4")
        require(self.table_points >= 16, "sim.contact.table_points", self.table_points, "must be >= 16")


@dataclass
class FSRConfig:
    """Velostat force-sensing resistor between crossed electrodes (one taxel).

    Conductance rises as a power of pressure (percolation of carbon contacts) and saturates
    once the contact spots merge: G = G_floor + G_sat x / (1 + x), x = (p / p_sat)^exponent.
    """

    exponent: float = 1.3
    saturation_kpa: float = 150.0  # pressure at half the saturated conductance
    saturated_kohm: float = 1.0  # 1 / G_sat for one 1.2 x 1.2 mm taxel
    floor_mohm: float = 5.0  # unloaded leakage resistance
    gain_cv: float = 0.10  # independent per-taxel conductance spread (electrode-Velostat contact)
    sheet_gain_cv: float = 0.10  # smooth conductance spread over the sheet (Velostat thickness, lamination)
    sheet_correlation_mm: float = 5.0  # correlation length of that smooth part
    hysteresis: float = 0.06  # relative play width: loading reads low, unloading high
    creep: float = 0.08  # fraction of the response that settles with time constant creep_s
    creep_s: float = 1.5
    layer_thickness_mm: float = 0.2  # FPCB + Velostat + FPCB

    def __post_init__(self) -> None:
        _positive(self.exponent, "sim.fsr.exponent", "power-law exponent must be > 0")
        _positive(self.saturation_kpa, "sim.fsr.saturation_kpa", "saturation pressure must be > 0 kPa")
        _positive(self.saturated_kohm, "sim.fsr.saturated_kohm")
        _positive(self.floor_mohm, "sim.fsr.floor_mohm")
        for key in ("gain_cv", "sheet_gain_cv"):
            v = getattr(self, key)
            require(v is not None and 0 <= v < 1, f"sim.fsr.{key}", v, "must lie in [0, 1)")
        require(self.sheet_correlation_mm is not None and self.sheet_correlation_mm >= 0,
                "sim.fsr.sheet_correlation_mm", self.sheet_correlation_mm, "must be >= 0 mm")
        _fraction(self.hysteresis, "sim.fsr.hysteresis")
        _fraction(self.creep, "sim.fsr.creep")
        _positive(self.creep_s, "sim.fsr.creep_s", "creep time constant must be > 0 s")
        _positive(self.layer_thickness_mm, "sim.fsr.layer_thickness_mm")


@dataclass
class ReadoutConfig:
    """Row-multiplexed passive matrix, column voltage dividers, 12-bit ADC (bits from `skin`)."""

    divider_kohm: float = 10.0
    supply_v: float = 3.3  # ADC reference is the supply (ratiometric)
    mux_on_ohm: float = 70.0  # CD74HC4067 on-resistance at 3.3-4.5 V
    leak_mohm: float = 100.0  # floating rows' leakage to ground (keeps the network regular)
    noise_counts: float = 1.5  # rms ADC + amplifier noise
    baseline_counts: float = 12.0  # mean per-taxel offset (ADC offset, laminate preload)
    baseline_sd_counts: float = 6.0
    crosstalk: bool = True  # solve the full row/column network (ghosting)
    scan_jitter_ms: float = 0.01  # rms jitter of each row's sampling instant

    def __post_init__(self) -> None:
        _positive(self.divider_kohm, "sim.readout.divider_kohm")
        _positive(self.supply_v, "sim.readout.supply_v")
        require(self.mux_on_ohm is not None and self.mux_on_ohm >= 0, "sim.readout.mux_on_ohm",
                self.mux_on_ohm, "must be >= 0 ohm")
        _positive(self.leak_mohm, "sim.readout.leak_mohm")
        for key in ("noise_counts", "baseline_counts", "baseline_sd_counts", "scan_jitter_ms"):
            v = getattr(self, key)
            require(v is not None and v >= 0, f"sim.readout.{key}", v, "must be >= 0")


@dataclass
class SimConfig:
    """The simulated world: the skin's physics plus the rig (`rig`, owned by the rig model)."""

    seed: int = 0
    spacer: SpacerConfig = field(default_factory=SpacerConfig)
    cover: CoverConfig = field(default_factory=CoverConfig)
    sheet: SheetConfig = field(default_factory=SheetConfig)
    contact: ContactConfig = field(default_factory=ContactConfig)
    fsr: FSRConfig = field(default_factory=FSRConfig)
    readout: ReadoutConfig = field(default_factory=ReadoutConfig)
    rig: RigConfig = field(default_factory=RigConfig)

    def __post_init__(self) -> None:
        require_seed("sim.seed", self.seed)


@dataclass
class WorldConfig:
    """`conf/world.yaml`: the simulated world without a protocol (preview, emulators, validation)."""

    skin: Any = MISSING  # SkinConfig
    sim: Any = MISSING  # SimConfig


@dataclass
class PreviewConfig(WorldConfig):
    """`conf/preview.yaml`: the world, where the preview PNG goes and (if set) the seed of its model."""

    out: str = "skin_preview.png"
    seed: int | None = None  # sim.seed for this preview; None: sim.seed as composed

    def __post_init__(self) -> None:
        if self.seed is not None:
            require_seed("seed", self.seed)


for _key, _fact in (("sim.contact.hemisphere_radius_mm", "the indenter's radius is layerskin_exp.rig.INDENTER_RADIUS_MM"),
                    ("sim.contact.rod_diameter_mm", "the rod's diameter is layerskin_exp.rig.ROD_DIAMETER_MM"),
                    ("sim.rig.gripper.rod_diameter_mm", "the rod's diameter is layerskin_exp.rig.ROD_DIAMETER_MM")):
    retire(_key, f"{_fact}, one fact for the contact model, the grip scene and the protocols")
for _key in ("marker_ids", "marker_size_mm", "marker_x_mm", "marker_y_mm", "dictionary"):
    retire(f"sim.rig.camera.{_key}", "the markers printed on the skin are the rig's: layerskin_exp.rig.MARKER_*")
# Dimensional keys carry their unit in the name.
for _section, _keys in (("spacer", ("modulus_kpa", "thickness_mm", "cell_mm", "wall_mm", "width_mm",
                                    "confinement_length_mm")),
                        ("cover", ("thickness_mm", "modulus_kpa"))):
    for _new in _keys:
        _old = _new.rsplit("_", 1)[0]
        retire(f"sim.{_section}.{_old}", f"renamed to sim.{_section}.{_new} so that the name carries its unit; "
                                         f"write sim.{_section}.{_new}=<same value> instead")


def _store() -> None:
    cs = ConfigStore.instance()
    cs.store(group="sim", name="sim_schema", node=SimConfig)
    cs.store(name="world_schema", node=WorldConfig)
    cs.store(name="preview_schema", node=PreviewConfig)


_store()


def load_sim(overrides: Sequence[str] = ()) -> SimConfig:
    """conf/sim/default.yaml with `sim.key=value` (or `key=value`) overrides, validated."""
    from layerskin_exp.config import compose

    return compose("world", [o if o.startswith("sim.") else f"sim.{o}" for o in overrides]).sim
