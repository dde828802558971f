"""The built wheel works outside the checkout: configs inside it, console scripts, no benchmarks.

The wheel is installed without dependencies into a fresh venv that sees this environment's
site-packages (for numpy, hydra, ...) through a .pth line, never this checkout; the trial then
runs from another directory through the `lsx-grip` console script.
"""

from __future__ import annotations

import os
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import pytest

from layerskin_exp import __version__
from layerskin_exp.log import load_session
from tests.protocols.conftest import TINY_GRIP

REPO = Path(__file__).resolve().parents[1]


def _run(cmd, **kw):
    return subprocess.run(cmd, capture_output=True, text=True, timeout=300, **kw)


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    root = tmp_path_factory.mktemp("wheel")
    r = _run([sys.executable, "-m", "pip", "wheel", str(REPO), "--no-deps", "--no-build-isolation", "-q",
              "-w", str(root / "dist")], cwd=REPO)
    assert r.returncode == 0, r.stderr[-2000:]
    (wheel,) = (root / "dist").glob("layerskin_exp-*.whl")
    venv = root / "venv"
    r = _run([sys.executable, "-m", "venv", "--without-pip", str(venv)])
    assert r.returncode == 0, r.stderr
    py = venv / "bin" / "python"
    site = Path(_run([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"]).stdout.strip())
    (site / "outer_env.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    r = _run([sys.executable, "-m", "pip", "--python", str(py), "install", "--no-deps", "-q", str(wheel)])
    assert r.returncode == 0, r.stderr[-2000:]
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    return wheel, venv, env, root


def test_wheel_contents(installed):
    wheel = installed[0]
    names = zipfile.ZipFile(wheel).namelist()
    tops = {n.split("/")[0] for n in names if not n.startswith("layerskin_exp-")}
    assert tops == {"layerskin_exp", "hardware", "protocols", "analysis"}  # no benchmarks
    confs = {n.removeprefix("layerskin_exp/conf/") for n in names if n.startswith("layerskin_exp/conf/")}
    in_checkout = {str(p.relative_to(REPO / "conf")) for p in (REPO / "conf").rglob("*.yaml")}
    assert confs == in_checkout
    assert "layerskin_exp/py.typed" in names
    ref = "layerskin_exp/sim/fem_reference/reference/"
    assert {ref + "bonded.npz", ref + "summary.json"} <= set(names)  # the FEM reference the validation reads
    # files read by path that are no config choice, kept beside their readers rather than in conf/
    assert {"layerskin_exp/sim/brackets.yaml", "layerskin_exp/sim/fem_reference/tolerances.yaml"} <= set(names)
    assert any(n.endswith("licenses/LICENSE") for n in names)
    entry = zipfile.ZipFile(wheel).read(next(n for n in names if n.endswith("entry_points.txt"))).decode()
    for script in ("lsx-calibrate", "lsx-grip", "lsx-report", "lsx-log", "lsx-live"):
        assert f"{script} = " in entry


# slow: a whole grip trial through the installed lsx-grip, its kernels compiled afresh: ~60 s.
@pytest.mark.slow
def test_console_script_runs_a_trial_outside_the_checkout(installed):
    _, venv, env, root = installed
    work = root / "elsewhere"
    work.mkdir()
    r = _run([str(venv / "bin" / "lsx-grip"), *TINY_GRIP, "data_root=data", "progress=false",
              "hydra.run.dir=run"], cwd=work, env=env)
    assert r.returncode == 0, r.stderr[-3000:]
    assert "complete" in r.stdout
    (path,) = (work / "data" / "grip_depth").glob("*/*.mcap")
    s = load_session(path)
    assert s.complete
    prov = s.metadata["provenance"]
    assert prov["git_commit"] is None and prov["overrides"][:len(TINY_GRIP)] == TINY_GRIP
    # the code that ran is the installed copy, and the Hydra job log carries the run
    assert str(venv) in _run([str(venv / "bin" / "python"), "-c", "import protocols; print(protocols.__file__)"],
                             cwd=work, env=env).stdout
    job_log = (work / "run" / "grip_depth.log").read_text()
    assert f"layerskin-exp {__version__}" in job_log and "trial g6_translation_t0 |" in job_log


def test_module_entry_and_install_hint(installed):
    _, venv, env, root = installed
    py = str(venv / "bin" / "python")
    r = _run([py, "-m", "layerskin_exp", "--help"], cwd=root, env=env)
    assert r.returncode == 0 and "lsx-grip" in r.stdout
    r = _run([str(venv / "bin" / "lsx-grip"), "-m", "hydra/launcher=slurm", "grip_depth=6,9"], cwd=root, env=env)
    # without the extra: what to install; with it (dev installs it) but no SLURM here: where to run
    assert r.returncode == 2 and ("pip install 'layerskin-exp[slurm]'" in r.stderr or "sbatch" in r.stderr), r.stderr
    r = _run([str(venv / "bin" / "lsx-grip"), "hardware=sim_schema"], cwd=root, env=env)
    assert r.returncode == 2 and "not an option" in r.stderr
    r = _run([str(venv / "bin" / "lsx-log"), "layout", "platform"], cwd=root, env=env)
    assert r.returncode == 0 and '"configById"' in r.stdout and '"maxValue": 4095' in r.stdout
    r = _run([str(venv / "bin" / "lsx-report"), "analysis=nope"], cwd=root, env=env)
    assert r.returncode == 2 and "analysis/nope" in r.stderr and "paper" in r.stderr  # the report's own glue


def test_commands_without_a_protocol_compose_from_the_wheel(installed):
    """The preview, the emulators and the model's validation compose conf/world.yaml from inside
    the installed package (the validation once read conf/ beside the sources: FileNotFoundError)."""
    _, venv, env, root = installed
    code = ("from layerskin_exp.sim import physics_checks, preview, validate\n"
            "from layerskin_exp.config import compose\n"
            "from hardware import emulate\n"
            "print(compose('validate', ['sim.seed=7']).sim.seed, compose('preview', ['seed=8']).seed,\n"
            "      emulate._compose('gripper', ['sim.seed=9'])[0].seed)\n")
    r = _run([str(venv / "bin" / "python"), "-c", code], cwd=root, env=env)
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stdout.split() == ["7", "8", "9"]
