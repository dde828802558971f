"""What the command line tells a newcomer, and how little it loads to say it: `--help` opens with
what the protocol does and its main keys; a file in a group folder is a choice of that group; the
answers that need no run (`--help`, a refused override, `--cfg job`) import none of the heavy
modules a run needs (their speed is measured in benchmarks/cli_help.py, not here)."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from tests.protocols.conftest import REPO, compose_app, run_cli

APPS = {"protocols.grip_depth": "grip_depth", "protocols.force_calibration": "force_calibration"}
GROUPS = [(app, g) for app in APPS.values() for g in ("sim", "skin", "hardware")] + [("grip_depth", "trajectory")]
HEAVY = ("numba", "cv2", "torch", "scipy", "mcap", "foxglove", "matplotlib")


@pytest.mark.parametrize(("app", "group"), GROUPS)
def test_every_file_in_a_group_folder_is_a_choice_of_that_group(app, group):
    for option in sorted((REPO / "conf" / group).glob("*.yaml")):
        cfg, typed = compose_app(app, [f"{group}={option.stem}"])  # validated: a refused option raises
        assert cfg[group] is not None and typed is not None


@pytest.mark.parametrize("module", list(APPS))
def test_help_opens_with_what_the_protocol_does_and_names_the_real_choices(module, tmp_path):
    r = run_cli(module, ["--help", "data_root=elsewhere"], tmp_path)
    assert r.returncode == 0, r.stderr[-2000:]
    lines = r.stdout.splitlines()
    assert lines[0].startswith(f"python -m {module} [key=value ...]: ")
    head = "\n".join(lines[:lines.index("== Config ==")])
    assert "Main keys" in head and "data_root=elsewhere: where the session files go" in head  # this command line's
    hardware = next(ln for ln in lines if ln.strip().startswith("hardware="))
    assert all(f"{p.stem} (" in hardware for p in (REPO / "conf" / "hardware").glob("*.yaml"))
    assert "\ndata_root: elsewhere\n" in r.stdout  # then the config
    assert list(tmp_path.iterdir()) == []  # help writes nothing


def test_help_refuses_a_bad_override_in_one_line(tmp_path):
    r = run_cli("protocols.grip_depth", ["--help", "grip_depth=abc"], tmp_path)
    assert r.returncode == 2 and r.stdout == ""
    assert "grip_depth=abc" in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr


@pytest.mark.parametrize("args", [["--help"], ["grip_depth=abc"], ["--cfg", "job"]])
def test_answers_that_need_no_run_import_no_heavy_module(args, tmp_path):
    env = {**os.environ, "PYTHONPATH": str(REPO), "HYDRA_FULL_ERROR": "0"}
    r = subprocess.run([sys.executable, "-X", "importtime", "-m", "protocols.grip_depth", *args, "data_root=d",
                        f"hydra.run.dir={tmp_path}/out"], cwd=tmp_path, env=env, capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == (2 if "grip_depth=abc" in args else 0), r.stderr[-2000:]
    imported = {ln.rsplit("|", 1)[1].strip().split(".")[0] for ln in r.stderr.splitlines()
                if ln.startswith("import time:")}
    assert "protocols" in imported  # the probe sees the command's own imports
    assert sorted(imported & set(HEAVY)) == []


# The report and the design map: their --help and a refused command line answer before the
# analysis stack (torch, scikit-learn, scipy.stats) loads; a run imports it where it is used.
ANALYSIS_ANSWERS = [("analysis.report", ["--help"], 0), ("analysis.report", ["sessions=nowhere"], 2),
                    ("analysis.design_map", ["--help"], 0), ("analysis.design_map", ["bogus=1"], 2)]


@pytest.mark.parametrize(("module", "args", "code"), ANALYSIS_ANSWERS)
def test_the_analysis_commands_answer_without_their_analysis_stack(module, args, code, tmp_path):
    env = {**os.environ, "PYTHONPATH": str(REPO), "HYDRA_FULL_ERROR": "0"}
    r = subprocess.run([sys.executable, "-X", "importtime", "-m", module, *args], cwd=tmp_path, env=env,
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == code, r.stderr[-2000:]
    imported = {ln.rsplit("|", 1)[1].strip().split(".")[0] for ln in r.stderr.splitlines()
                if ln.startswith("import time:")}
    assert "analysis" in imported
    assert sorted(imported & {"torch", "sklearn", "scipy", "numba", "cv2", "matplotlib"}) == []
