"""What `--help` tells a newcomer: what the protocol does and its main keys first, and only group
options that compose (a file in a group folder is a choice of that group, nothing else)."""

from __future__ import annotations

import pytest

from tests.protocols.conftest import REPO, compose_app, run_cli

APPS = {"protocols.grip_depth": "grip_depth", "protocols.force_calibration": "force_calibration"}


GROUPS = [(app, g) for app in APPS.values() for g in ("sim", "skin", "hardware")] + [("grip_depth", "trajectory")]


@pytest.mark.parametrize(("app", "group"), GROUPS)
def test_every_file_in_a_group_folder_is_a_choice_of_that_group(app, group):
    for option in sorted((REPO / "conf" / group).glob("*.yaml")):
        cfg, typed = compose_app(app, [f"{group}={option.stem}"])  # validated: a refused option raises
        assert cfg[group] is not None and typed is not None


@pytest.mark.parametrize("module", list(APPS))
def test_help_opens_with_what_the_protocol_does_and_lists_only_real_sim_choices(module, tmp_path):
    r = run_cli(module, ["--help", "data_root=elsewhere"], tmp_path)
    assert r.returncode == 0, r.stderr[-2000:]
    lines = r.stdout.splitlines()
    assert lines[0].startswith(f"python -m {module} [key=value ...]: ")
    head = "\n".join(lines[:lines.index("== Configuration groups ==")])
    assert "Main keys" in head and "data_root=elsewhere: where the session files go" in head
    (sim,) = [ln for ln in lines if ln.startswith("sim: ")]
    listed = {o for o in sim.removeprefix("sim: ").split(", ") if not o.endswith("_schema")}
    assert listed == {p.stem for p in (REPO / "conf" / "sim").glob("*.yaml")}
    assert list(tmp_path.iterdir()) == []  # help writes nothing
