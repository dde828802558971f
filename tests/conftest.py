import os

import pytest

os.environ.setdefault("MPLBACKEND", "Agg")


@pytest.fixture
def hydra_dirs(tmp_path):
    """Overrides that keep Hydra's run/sweep folders inside tmp_path."""
    return [f"hydra.run.dir={tmp_path}/out", f"hydra.sweep.dir={tmp_path}/multirun"]
