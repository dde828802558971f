"""Session-log write speed of the JSON streams: F/T wrench samples (the busiest, 1 kHz).

Figure: wrench samples per second through SessionWriter.write (the record's numbers checked,
encoded as JSON, framed, chunked, compressed, clock pairs kept) for 200,000 samples into a temp
file. Baseline, same run, same writer: the encoding of 2026-11-25, kept here (`_vec_then` and
`_dumps_then`: each vector through a numpy round trip and isfinite, json.dumps with arguments,
which builds a new encoder per message). A force-calibration campaign writes about 2,900 wrench
samples a trial, so this path was a fifth of a simulated campaign's time (cProfile).
"""

from __future__ import annotations

import json
import tempfile
import time
from pathlib import Path
from unittest import mock

import numpy as np

from layerskin_exp.log import SessionWriter
from layerskin_exp.log.session import schema as S
from layerskin_exp.log.session import writer as W
from layerskin_exp.types import Wrench


def _vec_then(values, n: int, name: str) -> list[float]:
    v = np.asarray(values, dtype=np.float64).reshape(-1)
    if v.size != n:
        raise ValueError(f"{name} has {v.size} values, expected {n}")
    out = v.tolist()
    if not np.all(np.isfinite(v)):
        out = [x if np.isfinite(x) else None for x in out]
    return out


def _dumps_then(obj) -> bytes:
    return json.dumps(obj, default=S.to_jsonable, allow_nan=False, separators=(",", ":")).encode()


def _samples(n: int) -> list[Wrench]:
    rng = np.random.default_rng(0)
    f, t = rng.normal(size=(n, 3)), rng.normal(size=(n, 3)) * 1e-2
    return [Wrench(f[i], t[i], i, 1_000_000 * i, 1_000_000 * i + 50_000) for i in range(n)]


def _rate(samples, folder: Path, name: str) -> float:
    with SessionWriter(folder / f"{name}.mcap") as w:
        t0 = time.process_time()
        for s in samples:
            w.write(s)
        dt = time.process_time() - t0
    return len(samples) / dt


def run(n: int = 200_000) -> dict:
    samples = _samples(n)
    with tempfile.TemporaryDirectory() as d:
        folder = Path(d)
        _rate(samples[:5000], folder, "warm")
        with mock.patch.object(W, "_vec", _vec_then), mock.patch.object(W.S, "dumps", _dumps_then):
            then = _rate(samples, folder, "then")
        now = _rate(samples, folder, "now")
    return {"samples": n, "measure": "wrench samples per CPU second",
            "baseline_2026_11_25_per_s": round(then), "current_per_s": round(now), "ratio": round(now / then, 2)}


if __name__ == "__main__":
    print(run())
