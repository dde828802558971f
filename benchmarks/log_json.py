"""Session-log write speed of the wrench stream (the busiest, 1 kHz), as protobuf against JSON.

Figure: wrench samples per second through SessionWriter.write (the record's numbers checked,
encoded, framed, chunked, compressed, clock pairs kept) for 200,000 samples into a temp file.
Baseline, same run, same writer: the JSON encoding of format_version 1 (`_json_then`: the shared
JSON encoder of 2026-11-25), which the session's own protobuf messages replaced so that generic
viewers decode the channel. A force-calibration campaign writes about 2,900 wrench samples a
trial.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path
from unittest import mock

import numpy as np

from layerskin_exp.log import SessionWriter
from layerskin_exp.log.session import schema as S
from layerskin_exp.log.session import writer as W
from layerskin_exp.types import Wrench


def _json_then(name: str, body: dict, t_ns: int) -> bytes:
    return S.dumps(body)


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
        with mock.patch.object(W.S, "encode", _json_then):
            then = _rate(samples, folder, "then")
        now = _rate(samples, folder, "now")
    return {"samples": n, "measure": "wrench samples per CPU second",
            "baseline_json_per_s": round(then), "current_per_s": round(now), "ratio": round(now / then, 2)}


if __name__ == "__main__":
    print(run())
