"""The shared config plumbing: range checks name the key, type errors name the key, keys that
repeated a fact of the rig are refused naming where the fact lives."""

from dataclasses import dataclass, field

import pytest
from omegaconf import OmegaConf

from layerskin_exp import rig
from layerskin_exp.config import ConfigError, SkinConfig, compose, require, validate


@dataclass
class _App:
    skin: SkinConfig = field(default_factory=SkinConfig)
    depth_mm: float = 1.0

    def __post_init__(self) -> None:
        require(self.depth_mm > 0, "depth_mm", self.depth_mm, "must be > 0")


def test_valid_config_builds_typed_objects():
    obj = validate(OmegaConf.structured(_App))
    assert isinstance(obj.skin, SkinConfig)
    assert obj.skin.taxel_centres_mm()[0] == pytest.approx(-11.25)
    assert obj.skin.taxel_centres_mm()[-1] == pytest.approx(11.25)


@pytest.mark.parametrize(
    "key,value,needle",
    [("skin.frame_period_ms", -2.0, "skin.frame_period_ms=-2.0"), ("depth_mm", -3.0, "depth_mm=-3.0")],
)
def test_out_of_range_value_names_the_key(key, value, needle):
    cfg = OmegaConf.structured(_App)
    OmegaConf.update(cfg, key, value)
    with pytest.raises(ConfigError, match=needle.replace(".", r"\.")):
        validate(cfg)


def test_wrong_type_is_refused_naming_the_key():
    cfg = OmegaConf.structured(_App)
    with pytest.raises(Exception) as ei:
        cfg.skin.frame_period_ms = "fast"
    assert "skin.frame_period_ms" in str(ei.value)


def test_the_skin_geometry_is_the_rigs():
    skin = SkinConfig()
    assert (skin.n_taxels, skin.pitch_mm, skin.electrode_mm, skin.adc_bits) == (
        rig.N_TAXELS, rig.PITCH_MM, rig.ELECTRODE_MM, rig.ADC_BITS)
    assert rig.SKIN_SHAPE == (rig.N_TAXELS, rig.N_TAXELS) and rig.ADC_MAX == 2**rig.ADC_BITS - 1
    assert rig.SENSING_HALF_WIDTH_MM == pytest.approx(-skin.taxel_centres_mm()[0] + rig.PITCH_MM / 2)


@pytest.mark.parametrize("override,where", [
    ("skin.n_taxels=8", "rig.py"), ("skin.adc_bits=10", "rig.py"), ("skin.pitch_mm=1.4", "rig.py"),
    ("sim.contact.rod_diameter_mm=20", "ROD_DIAMETER_MM"), ("sim.rig.gripper.rod_diameter_mm=20", "ROD_DIAMETER_MM"),
    ("sim.contact.hemisphere_radius_mm=3", "INDENTER_RADIUS_MM"), ("sim.rig.camera.marker_ids=[3,4]", "MARKER_"),
])
def test_a_value_that_would_contradict_the_rig_is_refused(override, where):
    import layerskin_exp.sim.config  # noqa: F401 - the world's schemas

    with pytest.raises(ConfigError, match=rf"^{override.split('=')[0]}: no longer a setting.*{where}"):
        compose("world", [override])
    assert compose("world", ["sim.seed=2"]).sim.seed == 2  # the same call composes a good override


def test_slurm_launcher_without_sbatch_is_refused_before_hydra(monkeypatch, capsys):
    """With the submitit plugin installed but no SLURM client here, the run is refused in one line
    saying where to run (Hydra's own error is a traceback from the launcher)."""
    pytest.importorskip("hydra_plugins.hydra_submitit_launcher")
    from layerskin_exp import cli

    monkeypatch.setenv("PATH", "/nonexistent")
    with pytest.raises(SystemExit) as e:
        cli._check_launcher(["-m", "hydra/launcher=slurm"])
    assert e.value.code == cli.EXIT_CONFIG
    err = capsys.readouterr().err
    assert "hydra/launcher=slurm" in err and "sbatch" in err
    cli._check_launcher(["-m", "hydra/launcher=submitit_local"])  # runs here: not refused


RENAMED = {"sim.spacer.modulus": "sim.spacer.modulus_kpa", "sim.spacer.thickness": "sim.spacer.thickness_mm",
           "sim.spacer.cell": "sim.spacer.cell_mm", "sim.spacer.wall": "sim.spacer.wall_mm",
           "sim.spacer.width": "sim.spacer.width_mm", "sim.spacer.confinement_length": "sim.spacer.confinement_length_mm",
           "sim.cover.thickness": "sim.cover.thickness_mm", "sim.cover.modulus": "sim.cover.modulus_kpa"}


@pytest.mark.parametrize("old,new", RENAMED.items())
def test_a_key_renamed_for_its_unit_is_refused_naming_the_new_one(old, new):
    import layerskin_exp.sim.config  # noqa: F401 - the world's schemas

    with pytest.raises(ConfigError, match=rf"^{old}: no longer a setting; renamed to {new} .* write {new}="):
        compose("world", [f"{old}=1.5"])
    assert compose("world", [f"{new}=1.5"]) is not None  # the new name takes the same value


def test_an_old_key_in_a_user_written_design_file_is_refused_in_one_line(tmp_path, monkeypatch, capsys):
    """A design of one's own (conf/design/<name>.yaml naming a lattice file of one's own) written
    with the old key is refused before anything runs, naming the new key and the file."""
    import shutil
    import sys

    import layerskin_exp.sim.config  # noqa: F401 - the world's schemas
    from layerskin_exp import cli, config

    conf = tmp_path / "conf"
    shutil.copytree(config.CONF_DIR, conf)
    (conf / "lattice" / "mine.yaml").write_text("# @package sim.spacer\nthickness_mm: 3.0\ncell_mm: 2.5\nwall: 0.6\n")
    (conf / "design" / "mine.yaml").write_text(
        "# @package _global_\ndefaults:\n  - /spacer_material: ecoflex_0010_thinned\n  - /lattice: mine\n")
    monkeypatch.setattr(config, "CONF_DIR", conf)
    monkeypatch.setattr(cli, "CONF_DIR", conf)
    with pytest.raises(ConfigError, match=r"^sim\.spacer\.wall: no longer a setting; renamed to sim\.spacer\.wall_mm"):
        compose("world", ["+design=mine"])
    monkeypatch.chdir(tmp_path)

    @cli.hydra_main("world")
    def app(cfg):
        pytest.fail("ran despite a retired key")

    for argv in (["-m", "+design=mine"], ["+design=mine"]):  # a sweep (preflight), a run (Hydra's composition)
        monkeypatch.setattr(sys, "argv", ["app", *argv])
        with pytest.raises(SystemExit) as e:
            cli.run_command("world", lambda: app)
        assert e.value.code == cli.EXIT_CONFIG
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "sim.spacer.wall_mm" in err and "lattice/mine" in err, err
    (conf / "lattice" / "mine.yaml").write_text("# @package sim.spacer\nthickness_mm: 3.0\ncell_mm: 2.5\nwall_mm: 0.6\n")
    assert compose("world", ["+design=mine"]).sim.spacer.wall_mm == 0.6  # the same file with the new key runs


@pytest.fixture
def own_conf(tmp_path, monkeypatch):
    """A copy of conf/ in tmp_path that the apps and compose() use."""
    import shutil

    from layerskin_exp import cli, config

    conf = tmp_path / "conf"
    shutil.copytree(config.CONF_DIR, conf)
    monkeypatch.setattr(config, "CONF_DIR", conf)
    monkeypatch.setattr(cli, "CONF_DIR", conf)
    monkeypatch.chdir(tmp_path)
    return conf


def _refused(monkeypatch, capsys, argv) -> str:
    """The one line a grip_depth command line is refused with (exit 2, before the app runs)."""
    import sys

    import protocols.config  # noqa: F401 - the protocols' schemas
    from layerskin_exp import cli

    @cli.hydra_main("grip_depth")
    def app(cfg):
        pytest.fail("ran despite a bad config")

    monkeypatch.setattr(sys, "argv", ["app", *argv])
    with pytest.raises(SystemExit) as e:
        cli.run_command("grip_depth", lambda: app)
    assert e.value.code == cli.EXIT_CONFIG
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    return err.strip()


@pytest.mark.parametrize("content", ["motion: torsion\n", "motion: torsion\n  bad: [unclosed\n"])
def test_a_group_option_may_not_lead_out_of_conf(own_conf, monkeypatch, capsys, content):
    import protocols.config  # noqa: F401

    (own_conf.parent / "elsewhere").mkdir()
    (own_conf.parent / "elsewhere" / "evil.yaml").write_text(content)
    line = ("configuration error: trajectory=../../elsewhere/evil: a trajectory option is a file in "
            "conf/trajectory/ (torsion, translation); it may not lead out of that folder")
    for argv in (["trajectory=../../elsewhere/evil"], ["-m", "trajectory=torsion,../../elsewhere/evil"],
                 ["trajectory=../../elsewhere/evil", "--help"]):
        assert _refused(monkeypatch, capsys, argv) == line
    with pytest.raises(ConfigError, match=r"^trajectory=\.\./\.\./elsewhere/evil: a trajectory option is a file"):
        compose("grip_depth", ["trajectory=../../elsewhere/evil"])


def test_a_yaml_syntax_error_is_one_line_naming_the_file_and_line(own_conf, monkeypatch, capsys):
    import protocols.config  # noqa: F401

    (own_conf / "trajectory" / "broken.yaml").write_text("motion: torsion\n  bad: [unclosed\n")
    line = ("configuration error: conf/trajectory/broken.yaml: YAML syntax error at line 2, column 6: "
            "mapping values are not allowed here")
    for argv in (["trajectory=broken"], ["-m", "trajectory=torsion,broken"]):
        assert _refused(monkeypatch, capsys, argv) == line
    with pytest.raises(ConfigError) as e:
        compose("grip_depth", ["trajectory=broken"])
    assert f"configuration error: {e.value}" == line
