"""`python -m protocols.grip_depth [overrides]`: one grip-depth trial (see conf/grip_depth.yaml); `-m` sweeps."""

from __future__ import annotations

import sys

import hydra
from omegaconf import DictConfig

from layerskin_exp.config import register_all

register_all()

from layerskin_exp.cli import CONF_DIR  # noqa: E402
from protocols.app import preflight, refuse_renamed, refuse_shared_files, run_app  # noqa: E402
from protocols.config import RENAMED_KEYS  # noqa: E402
from protocols.grip import run_grip_trial  # noqa: E402


@hydra.main(version_base="1.3", config_path=str(CONF_DIR), config_name="grip_depth")
def main(cfg: DictConfig) -> dict:
    result = run_app(cfg, "gripper", run_grip_trial)
    print(result.summary(), flush=True)
    return {**result.as_dict(), "summary": result.summary()}


def cli() -> None:
    """Console script: refuse a bad command line as a whole, then let Hydra run it."""
    refuse_renamed(sys.argv[1:], RENAMED_KEYS)
    preflight("grip_depth", sys.argv[1:])
    refuse_shared_files(sys.argv[1:])
    main()


if __name__ == "__main__":
    cli()
