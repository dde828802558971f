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
    "analysis.md": {"campaign-force:campaign-2026-12-04"},
    "export.md": {"lerobot-load:lerobot-load-check"},
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
    results = json.loads((DOCS / "campaign-2026-12-04" / "results.json").read_text())
    r2 = results["force"]["T-s5"]["Fx"]["r2"]
    assert f"| T-s5 | {r2:.3f} |" in (DOCS / "analysis.md").read_text()
    assert "`hardware.skin_board.port` |  | `/dev/ttyACM0`" in (DOCS / "bench" / "skin-board.md").read_text()


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
    from layerskin_exp.types import ProtocolEvent, TwoLayerFrame

    t0 = 10**18
    with SessionWriter(tmp_path / "session.mcap", metadata={"config": {"seed": 0}}, labels={"trial": 0}) as w:
        for i in range(40):
            counts = np.full((16, 16), 10 + i, np.uint16)
            w.write(TwoLayerFrame(counts, counts, i, t0 + int(i * 2.36e6), t0 + int(i * 2.36e6)))
        w.write_event(ProtocolEvent("phase", "press", t0 + 5_000_000, t0 + 5_000_000))
    text = (DOCS / "sessions.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    assert len(blocks) == 2
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


def _readme_commands() -> list[str]:
    """The shell commands of the README's bash blocks, continuation lines joined, comments cut."""
    text = (ROOT / "README.md").read_text()
    commands = []
    for block in re.findall(r"```bash\n(.*?)```", text, re.S):
        for line in block.replace("\\\n", " ").splitlines():
            line = line.split(" #", 1)[0].strip()
            if line:
                commands.append(line)
    return commands


def test_readme_entry_points_answer_help():
    """Every `python -m MODULE` the README shows answers --help (run side by side: seconds)."""
    modules = sorted(set(re.findall(r"python -m ([a-z_][\w.]*)", (ROOT / "README.md").read_text())))
    assert {"protocols.force_calibration", "protocols.grip_depth", "analysis.report"} <= set(modules)
    procs = {m: subprocess.Popen([sys.executable, "-m", m, "--help"], cwd=ROOT, stdout=subprocess.PIPE,
                                 stderr=subprocess.STDOUT, text=True) for m in modules}
    for module, proc in procs.items():
        out, _ = proc.communicate(timeout=120)
        assert proc.returncode == 0 and out.strip(), f"python -m {module} --help: {out[-2000:]}"
    make = subprocess.run(["make", "-n", "demo", "test"], cwd=ROOT, capture_output=True, text=True)
    if make.returncode != 127:  # make itself may be missing; the targets must exist where it is not
        assert make.returncode == 0, make.stderr


def test_readme_protocol_command_lines_compose():
    """The README's protocol command lines are valid configs: each composes and validates (the first
    and last job of a multirun), without running anything."""
    import shlex

    import protocols.config  # noqa: F401 - stores the protocol schemas
    from layerskin_exp.cli import expand_sweep
    from layerskin_exp.config import compose

    checked = 0
    for line in _readme_commands():
        m = re.match(r"python -m protocols\.(force_calibration|grip_depth)\b(.*)", line)
        if not m:
            continue
        args = shlex.split(m.group(2))
        if any(a.startswith("--") for a in args):
            continue
        overrides = [a for a in args if a != "-m" and not a.split("=", 1)[0].lstrip("+~").startswith("hydra")]
        jobs = expand_sweep(overrides) if "-m" in args else [overrides]
        for job in {tuple(jobs[0]), tuple(jobs[-1])}:
            compose(m.group(1), list(job))
        checked += 1
    assert checked >= 5
