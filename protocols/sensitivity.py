"""`python -m protocols.sensitivity [size=quick] [trajectories=R] [out=FILE] [params=[a,b]]` (a Hydra app on
conf/sensitivity.yaml, schema `SensitivityConfig`)

Screens the simulated bench's uncertain parameters (their brackets: layerskin_exp/sim/brackets.yaml) with
SALib's Morris method and prints which headline outcomes move and by how much.

Each Morris sample is a short calibration campaign on the simulated rig (`size`: default 3
positions x (2 presses + 2 slides); quick 2 x (1 + 1)), run in-process through the same protocol
code as `python -m protocols.force_calibration`, measured with the design map's outcome code
(analysis.design_map.campaign_outcomes): inter-layer shift per newton, linear shear R², the
superficial layer's shear R² (a ridge probe), position CV at 2 N, slide outcomes (fraction that
reached the 2 N stop, normal load while the shear is >= 1.5 N, the largest shear reached), and
the grip preload at g = 12 mm (the rod pressed g/2 past first contact through the gripper's
support compliance, from the skin model's mechanics). All samples share one seed (common random
numbers), so an elementary effect is the parameter's, not the noise's.

Writes a JSON (`out`, default outputs/sensitivity.json): per outcome and parameter Morris mu*
(mean |elementary effect|, in the outcome's unit per full bracket) and sigma, and the outcome's
range over all samples (the band over the brackets). `markdown_table(result)` renders it;
analysis.sensitivity_result reads it back for the report (`sensitivity=FILE`).
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from hydra.core.config_store import ConfigStore
from omegaconf import DictConfig, OmegaConf

from layerskin_exp.cli import hydra_main, refuse, run_command
from layerskin_exp.config import ConfigError, require, validate
from layerskin_exp.sim.config import BRACKETS_FILE, load_brackets

SIZES = {  # campaign per Morris sample
    "default": ["positions.count=3", "press.repeats=2", "slide.repeats=2"],
    "quick": ["positions.count=2", "press.repeats=1", "slide.repeats=1", "press.hold_s=0.05"],
    "tiny": ["positions.count=1", "press.repeats=1", "slide.repeats=1", "press.hold_s=0.05"],  # tests
}
GRIP_DEPTH_MM = 12.0
# outcome key -> (label, unit)
OUTCOMES = {
    "shift_per_n_mm": ("inter-layer shift per newton", "mm/N"),
    "cop_shift_at_2n_mm": ("inter-layer shift at 2 N shear", "mm"),
    "linear_r2_shear": ("linear shear R² (mean Fx, Fy)", ""),
    "superficial_r2_shear": ("superficial-only shear R² (ridge probe)", ""),
    "position_cv": ("position CV at 2 N", ""),
    "slides_shear_reached": ("slides reaching the 2 N stop", "fraction"),
    "slide_fz_at_shear_n": ("normal load while shear >= 1.5 N", "N"),
    "slide_max_shear_n": ("largest shear a slide reaches (median)", "N"),
    "grip_preload_n": (f"grip preload at g = {GRIP_DEPTH_MM:g} mm", "N"),
}


@dataclass
class SensitivityConfig:
    size: str = "default"
    trajectories: int = 4  # Morris r; samples = r (k + 1)
    num_levels: int = 4
    seed: int = 0
    params: list[str] = field(default_factory=list)  # empty: every screened entry of the brackets file
    out: str = "outputs/sensitivity.json"
    brackets: str = str(BRACKETS_FILE)

    def __post_init__(self) -> None:
        require(self.size in SIZES, "size", self.size, f"must be one of {', '.join(sorted(SIZES))}")
        require(self.trajectories >= 2, "trajectories", self.trajectories, "must be >= 2 (Morris sigma needs two)")
        try:
            problem(load_brackets(self.brackets), self.params)
        except OSError as e:
            raise ConfigError(f"brackets={self.brackets}: cannot read it ({e.strerror or e})") from None
        except ValueError as e:
            raise ConfigError(str(e)) from None


ConfigStore.instance().store(name="sensitivity_schema", node=SensitivityConfig)


def problem(brackets: dict, params: list[str] | None = None) -> dict:
    """The SALib problem over the screened brackets. A switch (`levels`) is screened as its level
    index in [0, n-1], rounded to a level."""
    keys = [k for k, v in brackets.items() if v.get("screen", True)]
    if params:
        unknown = [p for p in params if p not in brackets]
        if unknown:
            raise ValueError(f"params={unknown[0]}: not in the brackets file; choose from {sorted(brackets)}")
        keys = [k for k in keys if k in params]
    if not keys:
        raise ValueError("params: no screened parameter selected")
    bounds = [[0.0, float(len(brackets[k]["levels"]) - 1)] if "levels" in brackets[k]
              else [float(brackets[k]["low"]), float(brackets[k]["high"])] for k in keys]
    return {"num_vars": len(keys), "names": keys, "bounds": bounds}


def overrides_for(row: np.ndarray, prob: dict, brackets: dict) -> list[str]:
    """Hydra overrides of one sample."""
    out = []
    for key, x in zip(prob["names"], row, strict=True):
        levels = brackets[key].get("levels")
        value = levels[int(np.clip(np.rint(x), 0, len(levels) - 1))] if levels else f"{float(x):.6g}"
        out.append(f"{key}={value}")
    return out


def grip_preload_n(sim_cfg, skin_cfg, depth_mm: float = GRIP_DEPTH_MM) -> float:
    """Normal force of the rod pressed depth/2 (one finger's share of the closure) past first
    contact, through the gripper support's compliance (the skin model's own mechanics)."""
    from layerskin_exp.sim.skin import SkinModel

    k = sim_cfg.rig.gripper.support_stiffness_n_per_mm
    model = SkinModel(sim_cfg, skin_cfg, "rod", np.random.default_rng(0), k)
    z = -0.5 * depth_mm
    n = 50  # approach in steps (the mechanics carries state)
    t = np.linspace(0.0, 0.5, n)
    xyz = np.column_stack([np.zeros(n), np.zeros(n), np.linspace(0.5, z, n)])
    recs = model.step_many(t, xyz, np.full(n, np.pi / 2))
    return float(model.state_of(recs[-1]).force_n[2])


def run_sample(overrides: list[str], size: str, workdir: Path) -> dict:
    """One short campaign with these overrides; its outcomes (keys of OUTCOMES)."""
    import protocols.config  # noqa: F401 - stores the calibration app's schemas for Hydra
    from analysis.design_map import DesignMapConfig, campaign_outcomes
    from hardware import build_rig
    from layerskin_exp.config import compose
    from protocols.calibration import run_campaign

    typed = compose("force_calibration", [*SIZES[size], *overrides, f"data_root={workdir}", "progress=false"])
    rig = build_rig(typed, "platform")
    with rig:
        run_campaign(typed, rig, {"config": OmegaConf.to_container(OmegaConf.structured(typed), resolve=True),
                                  "backend": "sim", "provenance": {"overrides": overrides}})
    (folder,) = [p for p in (workdir / "force_calibration").iterdir() if p.is_dir()]
    o = campaign_outcomes(folder, DesignMapConfig(min_frames=10, ts5=False))  # no T-s5 per sample: not an outcome here
    slides = o.get("slides", {})
    return {"shift_per_n_mm": o.get("shift_per_n_mm"),
            "cop_shift_at_2n_mm": (o.get("cop_shift_at_2n") or {}).get("median_mm"),
            "linear_r2_shear": o.get("linear_r2_shear"), "superficial_r2_shear": o.get("superficial_r2_shear"),
            "position_cv": o.get("position_cv"),
            "slides_shear_reached": slides.get("stop_fractions", {}).get("shear_reached", 0.0),
            "slide_fz_at_shear_n": slides.get("fz_at_shear_n"), "slide_max_shear_n": slides.get("median_max_shear_n"),
            "grip_preload_n": grip_preload_n(typed.sim, typed.skin)}


def analyse(prob: dict, X: np.ndarray, Y: dict[str, np.ndarray], num_levels: int, seed: int) -> dict:
    """Morris mu*, sigma per outcome and parameter; an outcome missing in a sample (None) is
    filled with the outcome's median so one undefined sample does not void the screen (counted)."""
    from SALib.analyze import morris

    res = {}
    for key, y in Y.items():
        y = np.array([np.nan if v is None else v for v in y], float)
        missing = int(np.isnan(y).sum())
        if missing == len(y):
            res[key] = {"missing": missing, "reason": "undefined in every sample"}
            continue
        y = np.where(np.isnan(y), np.nanmedian(y), y)
        a = morris.analyze(prob, X, y, num_levels=num_levels, print_to_console=False, seed=seed)
        res[key] = {"range": [float(y.min()), float(y.max())], "missing": missing,
                    "mu_star": dict(zip(prob["names"], map(float, a["mu_star"]), strict=True)),
                    "sigma": dict(zip(prob["names"], map(float, np.nan_to_num(a["sigma"])), strict=True))}
    return res


def screen(cfg: SensitivityConfig, progress=print) -> dict:
    from SALib.sample import morris as morris_sample

    brackets = load_brackets(cfg.brackets)
    prob = problem(brackets, cfg.params)
    X = morris_sample.sample(prob, cfg.trajectories, num_levels=cfg.num_levels, seed=cfg.seed)
    Y: dict[str, list] = {k: [] for k in OUTCOMES}
    samples = []
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="lsx-sensitivity-") as tmp:
        for i, row in enumerate(X):
            ov = overrides_for(row, prob, brackets)
            o = run_sample(ov, cfg.size, Path(tmp) / f"s{i:03d}")
            for k in OUTCOMES:
                Y[k].append(o.get(k))
            samples.append({"overrides": ov, "outcomes": o})
            progress(f"sample {i + 1}/{len(X)} ({time.perf_counter() - t0:.0f} s): {' '.join(ov)}")
    return {"size": cfg.size, "campaign": SIZES[cfg.size], "trajectories": cfg.trajectories,
            "num_levels": cfg.num_levels, "seed": cfg.seed, "problem": prob,
            "brackets_file": "layerskin_exp/sim/brackets.yaml" if Path(cfg.brackets) == BRACKETS_FILE else str(cfg.brackets), "wall_s": time.perf_counter() - t0,
            "outcomes": {k: {"label": lab, "unit": u} for k, (lab, u) in OUTCOMES.items()},
            "morris": analyse(prob, X, Y, cfg.num_levels, cfg.seed), "samples": samples}


def markdown_table(result: dict, digits: int = 3) -> str:
    """Outcome rows, parameter columns: Morris mu* (sigma); last column the outcome's range."""
    names = result["problem"]["names"]
    short = [n.split(".")[-1] for n in names]
    lines = ["| outcome | " + " | ".join(short) + " | range over the brackets |",
             "|---" * (len(names) + 2) + "|"]
    for key, m in result["morris"].items():
        meta = result["outcomes"].get(key, {"label": key, "unit": ""})
        label = f"{meta['label']}" + (f" ({meta['unit']})" if meta["unit"] else "")
        if "mu_star" not in m:
            lines.append(f"| {label} | " + " | ".join("–" for _ in names) + f" | {m.get('reason', '')} |")
            continue
        top = max(m["mu_star"].values()) or 1.0
        cells = []
        for n in names:
            mu = m["mu_star"][n]
            txt = f"{mu:.{digits}g} ({m['sigma'][n]:.2g})"
            cells.append(f"**{txt}**" if mu >= 0.5 * top and mu > 0 else txt)
        lo, hi = m["range"]
        lines.append(f"| {label} | " + " | ".join(cells) + f" | {lo:.{digits}g} – {hi:.{digits}g} |")
    return "\n".join(lines)


@hydra_main("sensitivity")
def main(cfg: DictConfig) -> None:
    try:
        typed: SensitivityConfig = validate(cfg)
    except ConfigError as e:
        refuse(e)
    command(typed)


def command(cfg: SensitivityConfig) -> None:
    """The screen on its validated config: the table printed, the result written to cfg.out."""
    prob = problem(load_brackets(cfg.brackets), cfg.params)
    n = cfg.trajectories * (prob["num_vars"] + 1)
    print(f"Morris screen: {prob['num_vars']} parameters, {n} short campaigns ({cfg.size} size)", flush=True)
    res = screen(cfg, lambda s: print(s, file=sys.stderr, flush=True))
    out = Path(cfg.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(res, indent=1, default=float))
    print(markdown_table(res))
    print(f"\nmu* (sigma): mean |elementary effect|, the outcome's change per full bracket (a switch: per "
          f"step from its first to its last level), from steps of {cfg.num_levels / (2 * (cfg.num_levels - 1)):.2g} "
          f"bracket; bold: at least half the outcome's largest mu*. Written to {out} ({res['wall_s']:.0f} s)")


def cli() -> None:
    """`python -m protocols.sensitivity`: --help, a bad key or value refused in one line (exit 2), then the screen."""
    run_command("sensitivity", lambda: main)


if __name__ == "__main__":
    cli()
