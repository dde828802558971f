"""What every Hydra command line of the project shares: one entry path, refusing a bad config
before anything runs.

Every command that runs or measures (the protocols, the report, the design map, the sensitivity
screen, the design search, the simulator's preview and validation) is a Hydra app on conf/<name>.yaml, decorated by `hydra_main(name)`
(one config folder, one `version_base`) and started by `run_command(name, load_main, ...)`:
`--help` from one composition, the command's own checks of its command line, then `preflight`,
then Hydra. Only the file tools (`python -m layerskin_exp.log`, `protocols.sessions`, `hardware.emulate`, the
export, the demo) parse options with argparse (tests/test_entry.py holds all of this).

A command line's config is composed once. A run: Hydra composes it, and `RefuseBadConfig` (every
app's `hydra.callbacks.refuse_bad_config`) validates that composition before Hydra writes its run
folder; a composition Hydra refuses reaches `run_command` as its exception. A multirun:
`preflight(config_name, argv)` composes and validates every job of the sweep before any of them
runs (the sweep is refused as a whole), and the launcher composes each job when it starts it.
Either way a bad override ends the command with one readable line and exit code 2: nothing
connected, nothing written.

Kept in the core because the protocols' and the report's command lines share it; it names no
application (the caller has stored its schemas before calling it).
"""

from __future__ import annotations

import contextlib
import itertools
import logging
import os
import sys
from collections.abc import Callable, Iterable

import yaml
from hydra.core.override_parser.overrides_parser import OverridesParser
from hydra.errors import HydraException
from hydra.experimental.callback import Callback

from layerskin_exp import config as config_module
from layerskin_exp.config import (
    CONF_DIR,
    VERSION_BASE,
    ConfigError,
    check_group_options,
    check_retired,
    format_config_error,
    one_line,
)

__all__ = ["CONF_DIR", "EXIT_CONFIG", "EXIT_INTERRUPTED", "EXIT_TERMINATED", "RefuseBadConfig", "exit_now", "answer_help", "command_overrides", "expand_sweep", "hydra_main", "one_line", "override_problem",
           "override_values", "preflight", "refuse",
           "run_command"]


EXIT_CONFIG = 2
EXIT_INTERRUPTED = 130  # Ctrl-C stopped the run (protocols.app)
EXIT_TERMINATED = 143  # SIGTERM stopped it
# Hydra's own modes and alternative configs: Hydra handles them (no run, or a config of the user's)
HYDRA_MODES = ("--help", "-h", "--hydra-help", "--info", "-i", "--cfg", "-c", "--shell-completion", "-sc",
               "--config-path", "-cp", "--config-name", "-cn", "--config-dir", "-cd")
# Launchers that need an optional extra: Hydra's own error ("Could not load ...") names no fix.
LAUNCHER_EXTRAS = {"slurm": ("hydra_plugins.hydra_submitit_launcher", "slurm"),
                   "submitit_slurm": ("hydra_plugins.hydra_submitit_launcher", "slurm"),
                   "submitit_local": ("hydra_plugins.hydra_submitit_launcher", "slurm")}


class JobLogFile(logging.FileHandler):
    """The job log's file handler (conf/hydra/job_logging/*.yaml). Where the file cannot be
    written (a full disk), it says so once, in one line on stderr, and stops writing to it: the
    run goes on with its console, instead of a logging traceback for every record after."""

    _failed = False

    def emit(self, record: logging.LogRecord) -> None:
        if not self._failed:
            super().emit(record)

    def handleError(self, record: logging.LogRecord) -> None:
        exc = sys.exc_info()[1]
        if not isinstance(exc, OSError):
            super().handleError(record)
            return
        if not self._failed:
            self._failed = True
            print(f"warning: the job log {self.baseFilename} cannot be written ({exc.strerror or exc}); "
                  "the run goes on without it", file=sys.stderr, flush=True)
            with contextlib.suppress(OSError):
                self.close()

    def flush(self) -> None:
        with contextlib.suppress(OSError):
            super().flush()


def refuse(err: Exception) -> None:
    print(format_config_error(err), file=sys.stderr)
    sys.exit(EXIT_CONFIG)


def hydra_main(config_name: str):
    """The decorator of every Hydra app: conf/<config_name>.yaml from CONF_DIR, VERSION_BASE."""
    import hydra

    return hydra.main(version_base=VERSION_BASE, config_path=str(CONF_DIR), config_name=config_name)


def run_command(config_name: str, load_main: Callable[[], Callable[[], object]],
                before: Iterable[Callable[[list[str]], None]] = (),
                after: Iterable[Callable[[list[str]], None]] = ()) -> None:
    """The one entry path of a command that takes config (its console script and `python -m`).

    Answers `--help` (from one composition, before the command's heavy modules load), runs the
    command's own checks of its command line (`before` preflight, `after` it: each refuses with
    exit 2), `preflight` (a multirun's every job composed and validated), then runs the Hydra app
    `load_main()` returns (decorated by `hydra_main(config_name)`; loaded last, so a refused
    command line never imports it). A run's config is composed once, by Hydra, and validated by
    `RefuseBadConfig`; a composition Hydra refuses ends the command here with exit 2. The caller
    has stored its schemas. Reads sys.argv, as Hydra does."""
    argv = sys.argv[1:]
    answer_help(config_name, argv)
    for check in before:
        check(argv)
    preflight(config_name, argv)
    for check in after:
        check(argv)
    main = _exiting_at_once_when_stopped(load_main())
    if _is_multirun(argv) or any(a in HYDRA_MODES for a in argv):
        main()
        return
    RefuseBadConfig.started = False
    full_error = os.environ.get("HYDRA_FULL_ERROR")
    os.environ["HYDRA_FULL_ERROR"] = "1"  # Hydra raises a refused composition instead of printing it
    try:
        main()
    except (HydraException, yaml.YAMLError) as e:  # the composition refused, or a config file unreadable
        if RefuseBadConfig.started or full_error == "1":
            raise
        refuse(ConfigError(one_line(e)))
    finally:
        if full_error is None:
            os.environ.pop("HYDRA_FULL_ERROR", None)
        else:
            os.environ["HYDRA_FULL_ERROR"] = full_error


def _exiting_at_once_when_stopped(main: Callable[[], object]) -> Callable[[], object]:
    def run() -> object:
        try:
            return main()
        except SystemExit as e:
            if e.code in (EXIT_INTERRUPTED, EXIT_TERMINATED):
                exit_now(e.code)
            raise
    return run


def exit_now(code: int) -> None:
    """End a run that Ctrl-C or SIGTERM stopped, after its files are closed (protocols.app closes
    them before it exits): the exit hooks run and the logs and standard streams are flushed, then
    the process ends without tearing the interpreter's modules down. That teardown took 0.4 s of
    the second SIGTERM allows (process managers follow SIGTERM with SIGKILL)."""
    import atexit
    import logging

    atexit._run_exitfuncs()  # what the interpreter runs at exit, first: tqdm's, multiprocessing's, weakref finalizers
    logging.shutdown()
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    os._exit(code)


class RefuseBadConfig(Callback):
    """Hydra callback of every app (`hydra.callbacks.refuse_bad_config`): a run's config, as Hydra
    composed it, is validated (`layerskin_exp.config.validate`: types, ranges, unknown keys) before
    Hydra makes the run's folder; a bad one ends the command with one line and exit 2."""

    started = False  # the run got past its config (errors after this are the run's, not the config's)

    def on_run_start(self, config, **kwargs) -> None:
        from omegaconf import open_dict

        cfg = config.copy()  # the app's config: Hydra's own node dropped, as run_job does
        with open_dict(cfg):
            del cfg["hydra"]
        try:
            config_module.validate(cfg)
        except ConfigError as e:
            refuse(e)
        RefuseBadConfig.started = True


def _is_multirun(argv: list[str]) -> bool:
    return "-m" in argv or "--multirun" in argv


def command_overrides(argv: list[str]) -> list[str]:
    """The key=value overrides of a command line (not its options, not Hydra's own keys)."""
    return [a for a in argv if not a.startswith("-") and not a.split("=", 1)[0].lstrip("+~").startswith("hydra")]


def override_values(argv: list[str]) -> dict[str, str]:
    """key (without +/~) -> value as Hydra reads it (quotes removed, `'out="/a b"'` -> `/a b`) of
    each single-valued override of the command line. An override Hydra cannot parse is refused
    here in one line (exit 2), saying how to quote a value with spaces (override_problem)."""
    parser = OverridesParser.create()
    values: dict[str, str] = {}
    for arg in (a for a in argv if not a.startswith("-")):
        problem = override_problem(arg, argv)
        if problem:
            refuse(ConfigError(problem))
        o = parser.parse_override(arg)
        if not o.is_sweep_override() and isinstance(o.value(), str):
            values[o.get_key_element().lstrip("+~")] = o.value()
    return values


def override_problem(arg: str, argv: list[str]) -> str:
    """Why Hydra cannot parse the override `arg` of command line argv ('' if it can), in one line:
    an argument without '=' that is the rest of a value the shell split at a space, a value with
    characters Hydra reads as syntax, each with the quoting Hydra documents
    (`'key="/path/with space"'`)."""
    key, sep, value = arg.partition("=")
    if not sep:
        i = argv.index(arg)
        before = next((a for a in reversed(argv[:i]) if "=" in a and not a.startswith("-")), None)
        if before is not None:
            k, _, v = before.partition("=")
            return (f"{arg!r} is not key=value: the shell split a value at a space; quote it for the shell and for "
                    f"Hydra: '{k}=\"{v} {arg}\"'")
        return f"{arg!r} is not key=value"
    try:
        OverridesParser.create().parse_override(arg)
    except HydraException as e:
        why = (str(e).strip().splitlines() or [type(e).__name__])[0]
        if value[:1] not in ("'", '"'):
            return f"{arg}: {why}; quote a value with spaces or brackets for Hydra: '{key}=\"{value}\"'"
        return f"{arg}: {why}"
    return ""


def expand_sweep(overrides: list[str]) -> list[list[str]]:
    """The override lists of every job a basic-sweeper multirun would launch (cartesian product)."""
    parsed = OverridesParser.create().parse_overrides(overrides)
    choices = []
    for o in parsed:
        key = o.get_key_element()
        values = list(o.sweep_string_iterator()) if o.is_sweep_override() else [o.get_value_element_as_str()]
        choices.append([f"{key}={v}" for v in values])
    return [list(combo) for combo in itertools.product(*choices)]


def answer_help(config_name: str, argv: list[str]) -> None:
    """`--help` / `-h`: print the command's help and exit 0; otherwise return.

    The help is Hydra's `hydra.help.template` (conf/hydra/help/lsx.yaml: the command's
    `hydra.help.header`, then its config with this command line's overrides), rendered here from
    one composition. Hydra's own --help renders the same template but first lists every config
    group, copying the whole config repository for each of ~100 groups, whether the template
    shows the list or not: seconds on 2 cores (benchmarks/cli_help).
    """
    if not any(a in ("--help", "-h") for a in argv):
        return
    import string

    from hydra import compose, initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra
    from omegaconf import OmegaConf, open_dict

    overrides = command_overrides(argv)
    try:
        check_group_options(overrides)
    except ConfigError as e:
        refuse(e)
    GlobalHydra.instance().clear()
    try:
        with initialize_config_dir(config_dir=str(CONF_DIR), version_base=VERSION_BASE):
            cfg = compose(config_name=config_name, overrides=overrides, return_hydra_config=True)
        template = cfg.hydra.help.template  # the header's ${...} resolve against this command line
    except (HydraException, yaml.YAMLError) as e:
        refuse(ConfigError(one_line(e)))
    finally:
        GlobalHydra.instance().clear()
    with open_dict(cfg):
        del cfg["hydra"]
    print(string.Template(template).safe_substitute(CONFIG=OmegaConf.to_yaml(cfg)))
    sys.exit(0)


def preflight(config_name: str, argv: list[str]) -> None:
    """Refuse a bad command line before Hydra runs: the launcher, schema names given as options,
    retired keys, the override syntax; and for a multirun, compose and validate every job.

    A multirun's unknown group options (`hardware=foo`), type errors and range errors end it as
    one line and exit code 2, so a sweep is refused as a whole rather than failing at job 37. A
    single run is composed once, by Hydra (`RefuseBadConfig` validates it).
    """
    if any(a in HYDRA_MODES for a in argv):
        return  # Hydra's own modes and alternative configs: let Hydra handle them
    _check_launcher(argv)
    _refuse_schema_options(argv)
    overrides = command_overrides(argv)
    for arg in overrides:
        problem = override_problem(arg, argv)
        if problem:
            refuse(ConfigError(problem))
    multirun = _is_multirun(argv)
    try:
        check_retired(overrides)
        check_group_options(overrides)
    except ConfigError as e:
        refuse(e)
    try:
        jobs = expand_sweep(overrides) if multirun else [overrides]
    except HydraException as e:
        refuse(ConfigError(f"override: {one_line(e)}"))
    if not multirun:
        return  # the run's one composition is Hydra's (RefuseBadConfig)
    for job in jobs:  # every job of a sweep, before any of them runs
        try:
            config_module.compose(config_name, job)
        except ConfigError as e:
            refuse(e)


def _check_launcher(argv: list[str]) -> None:
    """hydra/launcher=slurm without the optional extra: say what to install, before Hydra fails."""
    import importlib.util
    import shutil

    for a in argv:
        key, _, value = a.partition("=")
        if key.lstrip("+~") != "hydra/launcher" or value not in LAUNCHER_EXTRAS:
            continue
        module, extra = LAUNCHER_EXTRAS[value]
        try:
            found = importlib.util.find_spec(module) is not None
        except ModuleNotFoundError:
            found = False
        if not found:
            refuse(ConfigError(f"hydra/launcher={value} needs the optional extra: "
                               f"pip install 'layerskin-exp[{extra}]' (from a checkout: pip install -e '.[{extra}]')"))
        if value != "submitit_local" and shutil.which("sbatch") is None:
            refuse(ConfigError(f"hydra/launcher={value}: no `sbatch` on this machine's PATH; submit from a "
                               "SLURM login node, or run here with hydra/launcher=joblib (or submitit_local)"))


def _refuse_schema_options(argv: list[str]) -> None:
    """`hardware=sim_schema`: a group's structured schema is what its options fill in, not an option."""
    for a in argv:
        key, sep, value = a.partition("=")
        if sep and "." not in key and not key.startswith("hydra") and value.strip().endswith("_schema"):
            refuse(ConfigError(f"{key.lstrip('+~')}={value}: '{value}' is the schema behind the "
                               f"'{key.lstrip('+~')}' options, not an option; pick one of the files in "
                               f"conf/{key.lstrip('+~')}/"))
