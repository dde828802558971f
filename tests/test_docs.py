"""The user guide (docs/, mkdocs.yml) builds, its generated tables are current, and what it quotes
from the code is still in the code.

- `mkdocs build --strict`: a broken link, a missing anchor or a page left out of the nav fails.
- every `<!-- generated: NAME -->` section equals what tools/doc_tables.py makes from its source
  (the configs, the schemas, the drivers, committed report outputs): a table edited by hand, or a
  source changed without regenerating the page, fails; `python tools/doc_tables.py` fixes it.
- each error quoted in docs/troubleshooting.md is printed by the code base as quoted.
- the README's relative links lead to files that exist.
"""

from __future__ import annotations

import importlib.util
import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
CODE = ("layerskin_exp", "hardware", "protocols", "analysis")


def _doc_tables():
    spec = importlib.util.spec_from_file_location("doc_tables", ROOT / "tools" / "doc_tables.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_guide_builds_strictly(tmp_path):
    if importlib.util.find_spec("mkdocs") is None:
        pytest.skip("mkdocs is not installed (it is in the dev extra: pip install -e '.[dev]')")
    r = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--config-file",
                        str(ROOT / "mkdocs.yml"), "--site-dir", str(tmp_path / "site")],
                       cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-4000:]
    assert (tmp_path / "site" / "troubleshooting" / "index.html").is_file()


def test_every_page_is_in_the_nav():
    """mkdocs only warns (strict: fails) about pages left out; this says which, without mkdocs."""
    nav = (ROOT / "mkdocs.yml").read_text()
    pages = sorted(str(p.relative_to(DOCS)) for p in DOCS.rglob("*.md"))
    assert [p for p in pages if p not in nav] == []


EXPECTED_SECTIONS = {
    "protocols.md": {"protocol-keys:force_calibration", "protocol-keys:grip_depth"},
    "simulator.md": {"sim-params", "brackets"},
    "export.md": {"lerobot-load:lerobot-load-check"},
    "analysis.md": {"campaign-force:campaign-2026-12-04b", "campaign-characterisation:campaign-2026-12-04b",
                    "study:force", "study:characterisation", "study:tracking", "study:slip"},
    "sessions.md": {"session-channels"},
    "benchmarks.md": {"benchmark-list:cpu-2core", "benchmark-run:cpu-2core"},
    **{f"bench/{page}.md": {f"device-options:{dev}", f"device-faults:{dev}"}
       for page, dev in (("skin-board", "skin_board"), ("platform", "platform"), ("netft", "netft"),
                         ("ur5e", "ur5e"), ("hande", "hande"), ("camera", "camera"))},
}


def test_generated_tables_match_their_sources():
    gen = _doc_tables()
    found = {}
    for page in gen.pages():
        found[str(page.relative_to(DOCS))] = {m.group("name") for m in gen.SECTION.finditer(page.read_text())}
        stale = gen.update(page, write=False)
        assert not stale, (f"{page.relative_to(ROOT)}: {stale} differ from their source; "
                           "regenerate with: python tools/doc_tables.py")
    for page, names in EXPECTED_SECTIONS.items():
        assert names <= found.get(page, set()), f"docs/{page} lost a generated section: {names}"


def test_generated_tables_hold_what_the_sources_say():
    """Spot checks that the generator reads the sources, not only itself."""
    protocols = (DOCS / "protocols.md").read_text()
    assert "| `safety.max_normal_force_n` | N | `6.0` |" in protocols
    assert "at most 10.0 (a hard ceiling of this rig; no config can raise it)" in protocols
    results = json.loads((DOCS / "campaign-2026-12-04b" / "results.json").read_text())
    r2 = results["force"]["T-s5"]["Fx"]["r2"]
    assert f"| T-s5 | {r2:.3f} |" in (DOCS / "analysis.md").read_text()
    assert "`hardware.skin_board.port` |  | `/dev/ttyACM0`" in (DOCS / "bench" / "skin-board.md").read_text()
    analysis = (DOCS / "analysis.md").read_text()
    cop = results["characterization"]["cop_shift"]["median_mm"]
    assert f"| {cop:.2f} mm (" in analysis
    from analysis import study

    assert f"| T-s5 | {study.FORCE['T-s5']['Fx']['r2']:.3f} |" in analysis  # the paper's Table II
    bench = json.loads((DOCS / "benchmarks" / "cpu-2core.json").read_text())
    page = (DOCS / "benchmarks.md").read_text()
    assert bench["date"] in page and bench["machine"]["cpu"] in page
    for name, figures in bench["results"].items():
        assert f"`{name}` ({figures['benchmark_wall_s']} s)" in page


# Each troubleshooting entry: fragments of its quoted message that the code prints literally (the
# variable parts, and Hydra's own words, are left out). Every fragment must appear in the page's
# quoted blocks and in the code base.
TROUBLES = {
    "1.": ["configuration error: ", "must be > 0 mm and at most safety.max_grip_depth_mm="],
    "2.": ["(check the spelling; ", "'+' cannot add a setting the schema does not have)"],
    "3.": [": no longer a setting; ", "a fact of the sensor defined once in layerskin_exp/rig.py"],
    "4.": ["could not connect the ", "skin board: cannot open serial port ",
           "holds it, and that this user may open it (group dialout)",
           "ft: no RDT data from the Net F/T at ", "arm: cannot connect to the UR controller at ",
           "and that ports 29999/30003/30004 are reachable", "gripper: cannot reach the Robotiq URCap socket at "],
    "5.": ["starts in alarm (homing required, or a limit or reset ",
           "home it with $H, or set hardware.platform.unlock_alarm=true to "],
    "6.": ["skin stalled: no frame for ", "check the board's power and USB link",
           "the trial in progress is kept as ", "rerun the same command to resume"],
    "7.": [" skin frames lost (limit max_lost_skin_frames=", "kept as .mcap.partial, rerun the same command to record "],
    "8.": ["recorded with another configuration (identity ",
           "Record this one under another data_root, or move that file away first",
           ": another SessionWriter is writing this file (", "Wait for that run to "],
    "9.": ["not permitted to raise this process's priority (needs root, CAP_SYS_NICE or an ",
           "runs at normal priority. Set %s=null to silence this."],
    "10.": [": no session files (*.mcap) under ", "point sessions= at the "],
    "11.": [": no `sbatch` on this machine's PATH; submit from a ", " needs the optional extra: "],
    "12.": [": an MCAP file but not a layerskin session (no '", "Open it with Foxglove or the mcap library instead."],
}


def _code_text() -> str:
    return "\n".join(p.read_text() for pkg in CODE for p in sorted((ROOT / pkg).rglob("*.py")))


def test_troubleshooting_quotes_the_code():
    page = (DOCS / "troubleshooting.md").read_text()
    entries = re.split(r"^### ", page, flags=re.M)[1:]
    assert len(entries) >= 10, "the troubleshooting page should cover the ten most likely errors"
    numbers = [e.split(" ", 1)[0] for e in entries]
    assert numbers == list(TROUBLES), "each entry needs its fragments in TROUBLES (and back)"
    code = _code_text()
    for entry, number in zip(entries, numbers, strict=True):
        quoted = "\n".join(re.findall(r"```\n(.*?)```", entry, re.S) + re.findall(r"`([^`\n]+)`", entry))
        for fragment in TROUBLES[number]:
            printed = fragment.replace("%s", "hardware.nice")
            assert printed in quoted, f"troubleshooting {number} no longer quotes {printed!r}"
            assert fragment in code, f"troubleshooting {number}: {fragment!r} is no longer in the code"


def test_readme_links_resolve():
    text = (ROOT / "README.md").read_text()
    targets = re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", text)
    missing = [t for t in targets if not re.match(r"^[a-z]+:", t) and not (ROOT / t).exists()]
    assert targets and missing == []


def test_readme_stays_a_front_door():
    lines = (ROOT / "README.md").read_text().splitlines()
    assert len(lines) <= 200
    text = "\n".join(lines).lower()
    for word in ("this session", "today", "fifteenth"):
        assert word not in text


def test_the_sessions_page_reads_a_session_as_written(tmp_path, monkeypatch, capsys):
    """Both reading examples of docs/sessions.md (the project's reader, the official mcap reader)
    run as written on a small session."""
    import numpy as np

    from layerskin_exp.log import SessionWriter
    from layerskin_exp.types import MarkerDetection, Pose, ProtocolEvent, TwoLayerFrame, Wrench

    t0 = 10**18
    with SessionWriter(tmp_path / "session.mcap", metadata={"config": {"seed": 0}}, labels={"trial": 0}) as w:
        for i in range(40):
            counts = np.full((16, 16), 10 + i, np.uint16)
            w.write(TwoLayerFrame(counts, counts, i, t0 + int(i * 2.36e6), t0 + int(i * 2.36e6)))
        w.write_event(ProtocolEvent("phase", "press", t0 + 5_000_000, t0 + 5_000_000))
        pose = Pose(np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]), "camera", t0, t0)
        for record in (Wrench(np.zeros(3), np.zeros(3), 0, t0, t0), MarkerDetection(0, pose, np.zeros((4, 2)), 0, t0, t0)):
            w.write(record)
    text = (DOCS / "sessions.md").read_text()
    # the channels table says what the writer writes: each channel of this file, read with the
    # mcap library, has its row with the same encoding and schema
    from mcap.reader import make_reader

    with open(tmp_path / "session.mcap", "rb") as fh:
        summary = make_reader(fh).get_summary()
    for channel in summary.channels.values():
        topic = re.sub(r"^/markers/\d+", "/markers/<id>", channel.topic)
        row = re.search(rf"^\| `{re.escape(topic)}` \|.*$", text, re.M)
        assert row, f"docs/sessions.md has no row for {channel.topic}"
        cells = [c.strip() for c in row.group(0).split("|")]
        assert cells[3].split()[0] == channel.message_encoding, (channel.topic, cells[3])
        assert cells[4] == f"`{summary.schemas[channel.schema_id].name}`", (channel.topic, cells[4])
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    assert len(blocks) == 2, "a new block of docs/sessions.md needs its run here"
    monkeypatch.chdir(tmp_path)
    for block in blocks:
        exec(compile(block, "docs/sessions.md", "exec"), {})
    out = capsys.readouterr().out
    assert "outcome:" in out and "phase press" in out


def test_the_version_is_one_and_released_in_the_changelog():
    import layerskin_exp

    declared = re.search(r'^version = "([^"]+)"', (ROOT / "pyproject.toml").read_text(), flags=re.M).group(1)
    assert declared == layerskin_exp.__version__
    changelog = (ROOT / "CHANGELOG.md").read_text()
    sections = re.findall(r"^## \[([^\]]+)\]", changelog, flags=re.M)
    assert sections[:2] == ["Unreleased", declared], "an Unreleased section, then this version's"
    assert re.search(rf"^## \[{re.escape(declared)}\] - \d{{4}}-\d{{2}}-\d{{2}}$", changelog, flags=re.M)


# ---- every command the README and the guide show ---------------------------------------------------
#
# Each line of a ```bash block of README.md or docs/**/*.md is a command the suite exercises in a
# cheap form, without running it:
#   python -m APP overrides      (a Hydra app: `run_command("NAME"` in its source) its overrides
#                                compose and validate in-process (a multirun: its first and last
#                                job), and `python -m APP --help` answers (once per app);
#   python -m MODULE [args]      (any other entry point, `mkdocs` too) the same line with --help
#                                answers, exit 0, and its help names every --option the line uses;
#   make TARGET                  `make -n TARGET` knows it;
#   pip install                  each extra `.[name]` is in pyproject.toml, a `torch==V` pin is the
#                                Makefile's.
# A block whose first line is a comment starting `# not checked:` is shown but not exercised (it
# says why, where the reader sees it). Anything else fails the test: add a form above or mark it.
NOT_CHECKED = "# not checked:"
STAND_INS = {"sensitivity": DOCS / "design-map" / "sensitivity.json"}  # app -> a committed output of it
FILE_TOOLS = {"touch"}  # coreutils a setup step uses: nothing of the project's to check


def _shown_pages() -> list[Path]:
    return [ROOT / "README.md", *sorted(DOCS.rglob("*.md"))]


def shown_commands(pages: list[Path] | None = None) -> list[tuple[str, list[str]]]:
    """(page, argv) of every command line of the pages' bash blocks: continuation lines joined,
    comments, `...` (the overrides above) and a shell redirection cut."""
    import shlex

    out = []
    for page in pages or _shown_pages():
        for block in re.findall(r"```bash\n(.*?)```", page.read_text(), re.S):
            if block.lstrip().startswith(NOT_CHECKED):
                continue
            for line in block.replace("\\\n", " ").splitlines():
                line = re.split(r"(?:^|\s)#", line, maxsplit=1)[0].strip()
                if not line:
                    continue
                argv = [a for a in shlex.split(line) if a != "..."]
                if ">" in argv:
                    argv = argv[: argv.index(">")]
                out.append((str(page.relative_to(ROOT)), argv))
    return out


def _hydra_app(module: str) -> str | None:
    """The config name a module's command line composes (`run_command("NAME", ...)`), or None."""
    spec = importlib.util.find_spec(module)
    if spec is None or spec.origin is None:
        return None
    origin = Path(spec.origin)
    if origin.name == "__init__.py" and (origin.parent / "__main__.py").is_file():
        origin = origin.parent / "__main__.py"
    m = re.search(r'run_command\("([\w.]+)"', origin.read_text())
    return m.group(1) if m else None


def _extras() -> set[str]:
    text = (ROOT / "pyproject.toml").read_text()
    section = text.split("[project.optional-dependencies]", 1)[1].split("\n[", 1)[0]
    return set(re.findall(r"^([\w-]+) = ", section, flags=re.M))


def _torch_pin() -> str:
    return re.search(r"torch==([\w.]+)", (ROOT / "Makefile").read_text()).group(1)


def plan_checks(commands):
    """What each shown command's cheap form is: (problems found without running anything,
    {app: [(page, overrides, multirun)]}, {help argv (tuple): [(page, options the line uses)]},
    [make targets])."""
    problems, compose_jobs, helps, make = [], {}, {}, []
    for page, argv in commands:
        where = f"{page}: {' '.join(argv)}"
        prog = Path(argv[0]).name
        if prog in FILE_TOOLS:
            continue
        if prog == "make":
            make += [a for a in argv[1:] if not a.startswith("-")]
            continue
        if prog == "pip" or argv[1:3] == ["-m", "pip"]:
            for a in argv:
                for extra in re.findall(r"^\.\[([\w,-]+)\]$", a):
                    problems += [f"{where}: no extra {e!r} in pyproject.toml"
                                 for e in extra.split(",") if e not in _extras()]
                if a.startswith("torch==") and a != f"torch=={_torch_pin()}":
                    problems.append(f"{where}: the Makefile pins torch=={_torch_pin()}")
            continue
        if prog == "mkdocs":
            argv = ["python", "-m", "mkdocs", *argv[1:]]
        if re.match(r"python3?$", Path(argv[0]).name) and len(argv) > 1 and argv[1].endswith(".py"):
            if not (ROOT / argv[1]).is_file():
                problems.append(f"{where}: no script {argv[1]} in the checkout")
                continue
            helps.setdefault((argv[1],), []).append((where, [a.split("=", 1)[0] for a in argv[2:] if a.startswith("--")]))
            continue
        if not (re.match(r"python3?$", Path(argv[0]).name) and len(argv) > 2 and argv[1] == "-m"):
            problems.append(f"{where}: no cheap form for this command (see the comment above NOT_CHECKED)")
            continue
        module, args = argv[2], argv[3:]
        if module == "protocols.live" and args and not args[0].startswith("-"):
            from protocols.live import PROTOCOLS

            # its own options against its --help; the rest is the protocol's command line, live=true
            helps.setdefault(("protocols.live",), []).append((where, [a for a in args[1:] if a.startswith("--")]))
            module, args = PROTOCOLS[args[0]], ["live=true", *(["live_hold=true"] if "--hold" in args else []),
                                                *[a for a in args[1:] if not a.startswith("--")]]
        app = _hydra_app(module)
        if app:
            helps.setdefault((module,), [])
            importlib.import_module(module)  # stores the schemas its config names
            if not any(a.startswith("--") for a in args):
                overrides = [a for a in args if a != "-m" and not re.match(r"[+~]*hydra[./]", a)]
                compose_jobs.setdefault(app, []).append((where, overrides, "-m" in args))
            continue
        positional = []
        for a in args:
            if a.startswith("-"):
                break
            positional.append(a)
        options = [a.split("=", 1)[0] for a in args if a.startswith("--")]
        helps.setdefault((module, *positional), []).append((where, options))
    return problems, compose_jobs, helps, make


def _answers_help(key: tuple[str, ...]) -> tuple[int, str]:
    run = [key[0], *key[1:]] if key[0].endswith(".py") else ["-m", *key]  # a script of the checkout, or a module
    r = subprocess.run([sys.executable, *run, "--help"], cwd=ROOT, capture_output=True, text=True, timeout=120)
    return r.returncode, r.stdout + r.stderr


def check_commands(commands) -> list[str]:
    """Every problem of the commands' cheap forms, one line each naming the page and command."""
    from concurrent.futures import ThreadPoolExecutor

    import protocols.config  # noqa: F401 - stores the protocol schemas
    from layerskin_exp.cli import expand_sweep
    from layerskin_exp.config import ConfigError, compose

    problems, compose_jobs, helps, make = plan_checks(commands)
    # A file one shown command writes (`out=FILE` of an app in STAND_INS) and another reads: a
    # committed output of that app stands in for it where it does not exist.
    written = {o.split("=", 1)[1]: STAND_INS[app] for app, jobs in compose_jobs.items() if app in STAND_INS
               for _, overrides, _ in jobs for o in overrides if o.startswith("out=")}

    def stood_in(override: str) -> str:
        key, _, value = override.partition("=")
        return f"{key}={written[value]}" if value in written and not (ROOT / value).exists() else override

    with ThreadPoolExecutor(max_workers=3) as pool:  # the --help processes, while composing here
        answers = dict(zip(helps, pool.map(_answers_help, helps), strict=True)) if helps else {}
        for app, jobs in compose_jobs.items():
            for where, overrides, multirun in jobs:
                try:
                    sweep = expand_sweep(overrides) if multirun else [overrides]
                    sweep = [[stood_in(o) for o in job] for job in sweep]
                    for job in {tuple(sweep[0]), tuple(sweep[-1])}:
                        compose(app, list(job))
                except ConfigError as err:
                    problems.append(f"{where}: {err}")
    for key, uses in helps.items():
        rc, out = answers[key]
        if rc != 0 or not out.strip():
            problems += [f"{where}: `python -m {' '.join(key)} --help` exit {rc}: {out.strip()[-300:]}"
                         for where, _ in uses[:1]] or [f"python -m {' '.join(key)} --help: exit {rc}"]
            continue
        for where, options in uses:
            problems += [f"{where}: {o} is not an option of python -m {' '.join(key)}"
                         for o in options if o != "--help" and not re.search(rf"{re.escape(o)}\b", out)]
    if make and shutil.which("make"):  # make itself may be missing; the targets must exist where it is not
        r = subprocess.run(["make", "-n", *sorted(set(make))], cwd=ROOT, capture_output=True, text=True)
        if r.returncode != 0:
            problems.append(f"make -n {' '.join(sorted(set(make)))}: {r.stderr.strip()}")
    return problems


def test_every_shown_command_has_a_cheap_form_that_passes():
    commands = shown_commands()
    assert len(commands) >= 40 and any(p == "README.md" for p, _ in commands)
    assert check_commands(commands) == []


def test_the_command_check_fails_on_what_is_wrong():
    """Each cheap form refuses its kind of mistake: an out-of-range override, an option the entry
    point does not have, a subcommand it does not have, an extra pyproject.toml lacks, a make
    target the Makefile lacks, a command with no cheap form."""
    broken = [("x.md", ["python", "-m", "protocols.grip_depth", "grip_depth=99"]),
              ("x.md", ["python", "-m", "protocols.grip_depth", "-m", "grip_depth=6,99"]),
              ("x.md", ["python", "-m", "layerskin_exp.log", "inspect", "FILE", "--no-such-option"]),
              ("x.md", ["python", "-m", "layerskin_exp.log", "no-such-subcommand"]),
              ("x.md", ["pip", "install", "-e", ".[no-such-extra]"]),
              ("x.md", ["frobnicate", "--now"]),
              ("x.md", ["python", "tools/lerobot_load_check.py", "DS", "S", "--no-such-flag"]),
              ("x.md", ["python", "tools/no_such_tool.py"])]
    if shutil.which("make"):
        broken.append(("x.md", ["make", "no-such-target"]))
    problems = check_commands(broken)
    for fragment in ("grip_depth=99", "grip_depth=6,99", "--no-such-option is not an option",
                     "layerskin_exp.log no-such-subcommand --help` exit 2", "no extra 'no-such-extra'",
                     "frobnicate --now: no cheap form", "--no-such-flag is not an option",
                     "no script tools/no_such_tool.py", *(["no-such-target"] if shutil.which("make") else [])):
        assert any(fragment in p for p in problems), (fragment, problems)
    assert len(problems) == len(broken)


def test_the_export_page_runs_as_written(tmp_path, monkeypatch, capsys):
    """docs/export.md's Python block, as written, on a small campaign folder of its name."""
    pytest.importorskip("pyarrow")
    spec = importlib.util.spec_from_file_location("log_records", ROOT / "tests" / "log" / "log_records.py")
    log_records = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(log_records)
    from layerskin_exp.log import SessionWriter

    design = tmp_path / "data" / "force_calibration" / "1844c3702b"
    design.mkdir(parents=True)
    labels = {"protocol": "force_calibration", "position_index": 0, "position_mm": [1.5, -2.0], "kind": "press",
              "repeat": 0, "direction_rad": None, "z_offset_mm": None}
    for repeat in range(2):
        with SessionWriter(design / f"pos000_press{repeat}.mcap", metadata={"protocol": "force_calibration"},
                           labels={**labels, "repeat": repeat}) as w:
            for record in log_records.records(200, seed=repeat):
                w.write(record)
    blocks = re.findall(r"```python\n(.*?)```", (DOCS / "export.md").read_text(), re.S)
    assert len(blocks) == 1, "a new block of docs/export.md needs its run here"
    monkeypatch.chdir(tmp_path)
    exec(compile(blocks[0], "docs/export.md", "exec"), {})
    assert (tmp_path / "calib_lerobot" / "meta" / "info.json").is_file() and capsys.readouterr().out.strip()


# page -> (its Python blocks, the test that runs every one of them as written)
PYTHON_BLOCKS = {
    "docs/sessions.md": (2, "tests/test_docs.py::test_the_sessions_page_reads_a_session_as_written"),
    "docs/export.md": (1, "tests/test_docs.py::test_the_export_page_runs_as_written"),
    "docs/estimation.md": (2, "tests/estimation/test_readme_bench.py::test_guide_bench_block_runs_as_written"),
}


def test_every_python_block_is_run_by_a_test():
    found = {}
    for page in _shown_pages():
        n = len(re.findall(r"```python\n", page.read_text()))
        if n:
            found[str(page.relative_to(ROOT))] = n
    assert found == {page: n for page, (n, _) in PYTHON_BLOCKS.items()}, "a page's Python blocks need a test"
    for page, (n, test) in PYTHON_BLOCKS.items():
        path, name = test.split("::")
        source = (ROOT / path).read_text()
        body = source[source.index(f"def {name}("):]
        body = body[: (re.search(r"\ndef ", body[1:]) or re.search("$", body)).start() + 1]
        assert Path(page).name in body and f"len(blocks) == {n}" in body, f"{test} no longer runs {page}'s blocks"
