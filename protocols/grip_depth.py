"""`python -m protocols.grip_depth [overrides]`: one grip-depth trial (see conf/grip_depth.yaml); `-m` sweeps."""

from __future__ import annotations

from omegaconf import DictConfig

import protocols.config  # noqa: F401 - stores this app's schemas (and those it builds on) for Hydra
from layerskin_exp.cli import hydra_main, run_command
from protocols.app import refuse_renamed, refuse_shared_files, run_app, sweep_job
from protocols.config import RENAMED_KEYS


@hydra_main("grip_depth")
def main(cfg: DictConfig) -> dict:
    return sweep_job(lambda: _trial(cfg))


def _trial(cfg: DictConfig) -> dict:
    from protocols.grip import prepare_grip, run_grip_trial  # not for --help or a refused command line

    result = run_app(cfg, "gripper", run_grip_trial, prepare_grip)
    return {**result.as_dict(), "summary": result.summary()}


def cli() -> None:
    """Console script: answer --help, refuse a bad command line as a whole, then let Hydra run it."""
    run_command("grip_depth", lambda: main, before=[lambda argv: refuse_renamed(argv, RENAMED_KEYS)],
                after=[refuse_shared_files])


if __name__ == "__main__":
    cli()
