"""Contact tables on disk: stored once, read back equal, solved again whenever the simulator's
code or the design changes, and a damaged file costs only the time."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from layerskin_exp.sim import table_cache
from layerskin_exp.sim.contact import ContactTables


def _tables(seed: int = 0) -> ContactTables:
    rng = np.random.default_rng(seed)
    fields = {}
    for f in dataclasses.fields(ContactTables):
        fields[f.name] = "rod" if f.name == "kind" else rng.random((4, 3) if f.name.endswith("kpa") else 4)
    return ContactTables(**fields)


@pytest.fixture
def disk(tmp_path, monkeypatch):
    monkeypatch.setattr(table_cache, "ENABLED", True)
    monkeypatch.setenv(table_cache.ENV, str(tmp_path))
    calls = []

    def build(seed=0):
        calls.append(seed)
        return _tables(seed)

    return tmp_path, calls, build


def test_second_process_reads_what_the_first_stored(disk):
    folder, calls, build = disk
    first = table_cache.load_or_build("design A", build)
    again = table_cache.load_or_build("design A", build)
    assert calls == [0]
    for f in dataclasses.fields(ContactTables):
        a, b = getattr(first, f.name), getattr(again, f.name)
        assert a == b if f.name == "kind" else np.array_equal(a, b)
    assert len(list((folder / "contact-tables").glob("*.npz"))) == 1


def test_a_changed_design_or_simulator_is_solved_again(disk, monkeypatch):
    _, calls, build = disk
    table_cache.load_or_build("design A", build)
    table_cache.load_or_build("design B", lambda: build(1))
    monkeypatch.setattr(table_cache, "_CODE_HASH", "an edited simulator")
    table_cache.load_or_build("design A", lambda: build(2))
    assert calls == [0, 1, 2]


def test_a_damaged_file_is_solved_again_and_replaced(disk):
    folder, calls, build = disk
    table_cache.load_or_build("design A", build)
    (path,) = (folder / "contact-tables").glob("*.npz")
    path.write_bytes(path.read_bytes()[:100])
    table_cache.load_or_build("design A", build)
    table_cache.load_or_build("design A", build)
    assert calls == [0, 0]


def test_empty_setting_or_disabled_means_no_disk(disk, monkeypatch):
    folder, calls, build = disk
    monkeypatch.setenv(table_cache.ENV, "")
    table_cache.load_or_build("design A", build)
    table_cache.load_or_build("design A", build)
    assert calls == [0, 0] and not any(folder.iterdir())
    monkeypatch.setenv(table_cache.ENV, str(folder))
    monkeypatch.setattr(table_cache, "ENABLED", False)
    table_cache.load_or_build("design A", build)
    assert calls == [0, 0, 0] and not any(folder.iterdir())


def test_the_code_hash_covers_the_simulator_and_the_rigs_facts(monkeypatch, tmp_path):
    import shutil

    from layerskin_exp import rig

    # a copy of the sim package and rig.py: an edit of either must change the hash
    pkg = tmp_path / "layerskin_exp"
    shutil.copytree(Path(table_cache.__file__).parent, pkg / "sim",
                    ignore=shutil.ignore_patterns("__pycache__", "fem_reference"))
    shutil.copy(rig.__file__, pkg / "rig.py")
    monkeypatch.setattr(table_cache, "__file__", str(pkg / "sim" / "table_cache.py"))

    def fresh_hash():
        monkeypatch.setattr(table_cache, "_CODE_HASH", None)
        return table_cache.code_hash()

    hashes = [fresh_hash()]
    for edited in (pkg / "rig.py", pkg / "sim" / "laminate.py"):
        edited.write_text(edited.read_text() + "\n# edited\n")
        hashes.append(fresh_hash())
    assert len(set(hashes)) == 3
