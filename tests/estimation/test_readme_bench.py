"""The Python blocks of docs/estimation.md (the sketch, and "use the estimator on your bench") run as
written, on a demo-shaped folder."""

import re
from pathlib import Path

import numpy as np

from layerskin_exp.log import SessionWriter
from layerskin_exp.types import TwoLayerFrame

PAGE = Path(__file__).resolve().parents[2] / "docs" / "estimation.md"


def _blocks() -> list[str]:
    """Every Python block of the page: the first one's sketch, then the bench block."""
    return re.findall(r"```python\n(.*?)```", PAGE.read_text(), re.S)


def test_guide_bench_block_runs_as_written(fitted_estimator, tmp_path, monkeypatch, capsys):
    est, raw = fitted_estimator
    est.save(tmp_path / "demo_out/report/models/T-s5.pt")
    path = tmp_path / "demo_out/sessions/grip_depth/abc/g12_translation_t0.mcap"
    path.parent.mkdir(parents=True)
    counts = raw[0][0]
    t0 = 10**18
    with SessionWriter(path, labels={"trial": 0}) as w:
        for i, c in enumerate(counts):
            t = t0 + int(i * 2.36e6)
            w.write(TwoLayerFrame(c[0], c[1], i, t, t))
    monkeypatch.chdir(tmp_path)
    blocks = _blocks()
    assert len(blocks) == 2, "a new block of docs/estimation.md needs its run here"
    for block in blocks:
        exec(compile(block, "docs/estimation.md", "exec"), {})
    out = capsys.readouterr().out
    assert out.startswith("None\n"), "the first block: no estimate before the baseline is in"
    last = re.search(r"last estimate: \[(.*)\] N", out)
    # the live estimate of the last complete frame matches the offline path on the same counts
    offline = est.force_from_counts(counts)
    got = np.array(last.group(1).split(), float)
    assert got.shape == (3,) and np.all(np.isfinite(got))
    assert np.abs(got[None] - offline.round(2)).max(axis=1).min() < 0.02
