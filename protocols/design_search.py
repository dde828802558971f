"""`python -m protocols.design_search -m hydra/sweeper=design_search [overrides]`: search the spacer
design space (conf/hydra/sweeper/design_search.yaml) for sensitivity and range.

The task is the calibration campaign itself (conf/force_calibration.yaml, the same app and the
same design folders as `python -m protocols.force_calibration`); after it, the campaign's
sessions are measured as the design map measures them (analysis.design_map.campaign_outcomes)
and the job returns the two objectives the sweeper maximises: the magnitude of the inter-layer
shift per newton (mm/N; its sign only names the leading layer, see analysis.design_map) and the
top of the estimable shear range (N). A design whose outcome is undefined (no
slide reached a measurable shear) scores 0 on it. A trial already complete is not run again, so
a resumed search re-measures its designs at no simulation cost.
"""

from __future__ import annotations

from pathlib import Path

from omegaconf import DictConfig, OmegaConf

import protocols.config  # noqa: F401 - stores the calibration app's schemas for Hydra
from layerskin_exp.cli import hydra_main, run_command
from protocols.app import run_app
from protocols.identity import design_id

OBJECTIVES = ("shift_per_n_mm", "shear_high_n")


def objectives(folder: Path) -> list[float]:
    from analysis.design_map import DesignMapConfig, campaign_outcomes

    o = campaign_outcomes(folder, DesignMapConfig(min_frames=10, ts5=False))  # its objectives need no CNN
    return [abs(float(o.get(k) or 0.0)) for k in OBJECTIVES]


@hydra_main("force_calibration")
def main(cfg: DictConfig) -> list[float]:
    from protocols.calibration import PROTOCOL, run_campaign  # the campaign's stack: not for --help

    run_app(cfg, "platform", run_campaign)
    folder = Path(cfg.data_root) / PROTOCOL / design_id(OmegaConf.to_container(cfg, resolve=True))
    values = objectives(folder)
    print(f"design {folder.name}: " + ", ".join(f"{k} {v:.3f}" for k, v in zip(OBJECTIVES, values, strict=True)))
    return values


if __name__ == "__main__":
    run_command("force_calibration", lambda: main)
