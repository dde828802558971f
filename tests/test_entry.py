"""One way in: every command that takes config is a Hydra app through `layerskin_exp.cli`
(`hydra_main`, one config folder and `version_base`), no module parses `key=value` itself
(`OmegaConf.from_dotlist`) or reads a YAML around the schemas (`OmegaConf.load`: only the one
checked reader of the brackets file, which is no config), and argparse is for the file tools.
Read from the source with `ast`, so a lazy import or a call inside a function counts too."""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("layerskin_exp", "hardware", "protocols", "analysis")
HYDRA_MAIN = {"layerskin_exp/cli.py"}  # hydra_main(name): the decorator every app uses
YAML_READERS = {"layerskin_exp/sim/config.py"}  # load_brackets: the brackets file, checked entry by entry
# The file tools: options, not config (a file to inspect, a device to emulate, an artifact to export).
ARGPARSE = {"layerskin_exp/log/cli.py", "layerskin_exp/estimation/export.py", "layerskin_exp/demo.py",
            "layerskin_exp/sim/fem_reference/__main__.py", "layerskin_exp/sim/fem_reference/yardstick3d.py",
            "layerskin_exp/sim/fem_reference/alignment.py", "protocols/sessions.py", "hardware/emulate.py"}


def entry_problems(repo: Path) -> list[str]:
    out = []
    for pkg in PACKAGES:
        for path in sorted((repo / pkg).rglob("*.py")):
            rel = str(path.relative_to(repo))
            tree = ast.parse(path.read_text(), rel)
            for node in ast.walk(tree):
                if isinstance(node, ast.Attribute):
                    name = f"{ast.unparse(node.value)}.{node.attr}"
                    if name == "hydra.main" and rel not in HYDRA_MAIN:
                        out.append(f"{rel}: hydra.main (decorate with layerskin_exp.cli.hydra_main)")
                    elif name == "OmegaConf.from_dotlist":
                        out.append(f"{rel}: OmegaConf.from_dotlist (make the command a Hydra app)")
                    elif name == "OmegaConf.load" and rel not in YAML_READERS:
                        out.append(f"{rel}: OmegaConf.load (compose the config: layerskin_exp.config.compose)")
                elif isinstance(node, ast.Import | ast.ImportFrom):
                    names = [a.name for a in node.names] + ([node.module] if isinstance(node, ast.ImportFrom) else [])
                    if "argparse" in names and rel not in ARGPARSE:
                        out.append(f"{rel}: argparse (a command that takes config is a Hydra app)")
    return sorted(set(out))


# Every command that takes config, and its config: a Hydra app (`hydra_main(name)`) started by
# `run_command(name, ...)` on conf/<name>.yaml.
HYDRA_APPS = {
    "protocols/force_calibration.py": "force_calibration",
    "protocols/grip_depth.py": "grip_depth",
    "protocols/design_search.py": "force_calibration",
    "protocols/sensitivity.py": "sensitivity",
    "analysis/report.py": "report",
    "analysis/design_map.py": "design_map",
    "layerskin_exp/sim/preview.py": "preview",
    "layerskin_exp/sim/validate.py": "validate",
}


def app_problems(repo: Path, apps: dict[str, str]) -> list[str]:
    out = []
    for rel, name in apps.items():
        calls = {(n.func.id, n.args[0].value) for n in ast.walk(ast.parse((repo / rel).read_text(), rel))
                 if isinstance(n, ast.Call) and isinstance(n.func, ast.Name) and n.args
                 and isinstance(n.args[0], ast.Constant)}
        out += [f"{rel}: no {f}({name!r})" for f in ("hydra_main", "run_command") if (f, name) not in calls]
        if not (repo / "conf" / f"{name}.yaml").is_file():
            out.append(f"{rel}: no conf/{name}.yaml")
    return out


def test_every_command_that_takes_config_is_a_hydra_app_started_by_run_command():
    assert app_problems(REPO, HYDRA_APPS) == []


def test_the_app_check_sees_a_command_outside_the_entry(tmp_path):
    (tmp_path / "conf").mkdir()
    (tmp_path / "conf" / "preview.yaml").write_text("")
    (tmp_path / "a.py").write_text("def main(argv):\n    compose('preview', argv)\n")  # the preview before
    (tmp_path / "b.py").write_text("@hydra_main('preview')\ndef main(cfg): ...\nrun_command('preview', lambda: main)\n")
    (tmp_path / "c.py").write_text("@hydra_main('validate')\ndef main(cfg): ...\nrun_command('validate', lambda: main)\n")
    assert app_problems(tmp_path, {"a.py": "preview", "b.py": "preview", "c.py": "validate"}) == [
        "a.py: no hydra_main('preview')", "a.py: no run_command('preview')", "c.py: no conf/validate.yaml"]


def test_every_command_enters_one_way():
    assert entry_problems(REPO) == []


def test_the_check_sees_each_other_way_in(tmp_path):
    for pkg in PACKAGES:
        (tmp_path / pkg).mkdir()
    (tmp_path / "analysis" / "a.py").write_text(
        "import hydra\n@hydra.main(version_base=None, config_path='c', config_name='x')\ndef main(cfg): ...\n")
    (tmp_path / "analysis" / "b.py").write_text(
        "def parse(argv):\n    from omegaconf import OmegaConf\n    return OmegaConf.from_dotlist(argv)\n")
    (tmp_path / "layerskin_exp").joinpath("c.py").write_text("from omegaconf import OmegaConf\nOmegaConf.load('x.yaml')\n")
    (tmp_path / "protocols" / "d.py").write_text("def cli():\n    import argparse\n")
    (tmp_path / "hardware" / "emulate.py").write_text("import argparse\n")  # a file tool: allowed
    assert entry_problems(tmp_path) == [
        "analysis/a.py: hydra.main (decorate with layerskin_exp.cli.hydra_main)",
        "analysis/b.py: OmegaConf.from_dotlist (make the command a Hydra app)",
        "layerskin_exp/c.py: OmegaConf.load (compose the config: layerskin_exp.config.compose)",
        "protocols/d.py: argparse (a command that takes config is a Hydra app)",
    ]


# ---------------------------------------------------------------- one composition per command line


def _count_compositions(monkeypatch) -> list[str]:
    """Every composition of a config (Hydra's apps and its compose API both load it here)."""
    from hydra._internal.config_loader_impl import ConfigLoaderImpl

    seen: list[str] = []
    load = ConfigLoaderImpl.load_configuration

    def counting(self, config_name, *args, **kwargs):
        seen.append(config_name)
        return load(self, config_name, *args, **kwargs)

    monkeypatch.setattr(ConfigLoaderImpl, "load_configuration", counting)
    return seen


def _bare_app_compositions(monkeypatch, config_name: str, argv: list[str]) -> int:
    """How many compositions Hydra's own app makes for this command line (Hydra 1.3 composes a
    run twice: once to read hydra.mode, once to run), the app started without run_command."""
    from layerskin_exp.cli import hydra_main

    @hydra_main(config_name)
    def bare(cfg):
        return None

    with monkeypatch.context() as m:
        m.setattr(sys, "argv", [config_name, *argv])
        seen = _count_compositions(m)
        bare()
    return len(seen)


@pytest.mark.parametrize("argv", [["seed=4", "sim.spacer.modulus_kpa=20"], ["--cfg", "job"]])
def test_a_command_line_composes_only_where_hydra_does(argv, tmp_path, monkeypatch, capsys):
    """A run and `--cfg job` through run_command compose no more than Hydra's app itself: no
    preflight or check composes the config again (the preview, its render replaced)."""
    import layerskin_exp.sim.config  # noqa: F401 - the preview's schemas
    from layerskin_exp.sim import preview

    monkeypatch.chdir(tmp_path)
    hydra_own = _bare_app_compositions(monkeypatch, "preview", argv)
    monkeypatch.setattr(preview, "render", lambda out, sim, skin: out)
    monkeypatch.setattr(sys, "argv", ["preview", *argv])
    seen = _count_compositions(monkeypatch)
    preview.cli()
    assert len(seen) == hydra_own, seen


def test_help_composes_once(tmp_path, monkeypatch, capsys):
    from layerskin_exp.sim import preview

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "argv", ["preview", "--help"])
    seen = _count_compositions(monkeypatch)
    with pytest.raises(SystemExit) as e:
        preview.cli()
    assert e.value.code == 0 and seen == ["preview"]


def test_a_refused_run_is_refused_from_hydras_composition(tmp_path, monkeypatch, capsys):
    """A bad value in a run: refused (exit 2, one line) by RefuseBadConfig from Hydra's composition,
    with no composition of its own and before Hydra writes anything."""
    from layerskin_exp.sim import validate

    monkeypatch.chdir(tmp_path)
    argv = ["sim.spacer.modulus_kpa=-1", f"hydra.run.dir={tmp_path}/out"]
    hydra_own = _bare_app_compositions(monkeypatch, "validate", [f"hydra.run.dir={tmp_path}/bare"])
    monkeypatch.setattr(validate, "report", lambda sim: pytest.fail("ran the checks despite a bad value"))
    monkeypatch.setattr(sys, "argv", ["validate", *argv])
    seen = _count_compositions(monkeypatch)
    with pytest.raises(SystemExit) as e:
        validate.cli()
    assert e.value.code == 2 and len(seen) == hydra_own, seen
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "sim.spacer.modulus_kpa=-1" in err, err
    assert not (tmp_path / "out").exists()  # refused before Hydra made the run's folder
