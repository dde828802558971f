"""`python -m protocols.force_calibration [overrides]`: the force-calibration campaign (see conf/force_calibration.yaml)."""

from __future__ import annotations

from omegaconf import DictConfig

import protocols.config  # noqa: F401 - stores this app's schemas (and those it builds on) for Hydra
from layerskin_exp.cli import hydra_main, run_command
from protocols.app import refuse_shared_files, run_app, sweep_job


@hydra_main("force_calibration")
def main(cfg: DictConfig) -> dict:
    return sweep_job(lambda: _campaign(cfg))


def _campaign(cfg: DictConfig) -> dict:
    from protocols.calibration import run_campaign  # not for --help or a refused command line

    results = run_app(cfg, "platform", run_campaign)
    return {"summary": f"{len(results)} trials run", "trials": [r.as_dict() for r in results]}


def cli() -> None:
    """Console script: answer --help, refuse a bad command line as a whole, then let Hydra run it."""
    run_command("force_calibration", lambda: main, after=[refuse_shared_files])


if __name__ == "__main__":
    cli()
