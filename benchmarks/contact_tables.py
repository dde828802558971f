"""Contact tables: solving a design's tables against reading them from the disk cache.

Figure: seconds per process to get the default design's tables, for the hemisphere (the
calibration campaign) and the rod (each grip job), solved (`contact.build_tables`, the baseline:
what every process did before the disk cache) and read back (`table_cache.load_or_build` on a
stored file), same run, in a temporary cache folder. Both are CPU seconds (time.process_time).
"""

from __future__ import annotations

import os
import tempfile
import time
from unittest import mock

from layerskin_exp.sim import table_cache
from layerskin_exp.sim.config import SimConfig
from layerskin_exp.sim.contact import build_tables


def run() -> dict:
    sim = SimConfig()
    res: dict = {"measure": "CPU seconds per process"}
    with tempfile.TemporaryDirectory() as d, mock.patch.dict(os.environ, {table_cache.ENV: d}), \
            mock.patch.object(table_cache, "ENABLED", True):
        for kind in ("hemisphere", "rod"):
            key = repr(("benchmark", kind))
            t0 = time.process_time()
            table_cache.load_or_build(key, lambda kind=kind: build_tables(sim, kind))  # solves and stores
            solved = time.process_time() - t0
            t0 = time.process_time()
            table_cache.load_or_build(key, lambda: (_ for _ in ()).throw(AssertionError("not cached")))
            read = time.process_time() - t0
            res[f"{kind}_solved_s"] = round(solved, 2)
            res[f"{kind}_read_s"] = round(read, 4)
            res[f"{kind}_ratio"] = round(solved / max(read, 1e-6))
    return res


if __name__ == "__main__":
    print(run())
