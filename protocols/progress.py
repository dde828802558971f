"""Progress across a Hydra multirun, where each job is one trial.

A Hydra callback (configured under `hydra.callbacks` in both primary configs): at the start of a
multirun it counts the jobs and notes the start time in the sweep folder; after each job (in
whatever process or node ran it) it appends the job's result to `sweep_progress.jsonl` there and
prints one progress line (done/left, ETA) plus the trial summary; at the end it prints a tally.
Works the same with the basic, joblib and SLURM launchers (the sweep folder is shared).
"""

from __future__ import annotations

import json
import math
import time
from collections import Counter
from pathlib import Path
from typing import Any

from hydra.core.utils import JobReturn, JobStatus
from hydra.experimental.callback import Callback
from omegaconf import DictConfig
from tqdm import tqdm

PLAN_FILE = "sweep_progress.json"
LOG_FILE = "sweep_progress.jsonl"


def _sweep_dir(config: DictConfig) -> Path:
    return Path(str(config.hydra.sweep.dir))


def count_jobs(overrides: list[str]) -> int:
    from layerskin_exp.cli import expand_sweep

    return len(expand_sweep([o for o in overrides if not o.split("=", 1)[0].lstrip("+~").startswith("hydra")]))


class SweepProgress(Callback):
    def on_multirun_start(self, config: DictConfig, **kwargs: Any) -> None:
        sweep = _sweep_dir(config)
        sweep.mkdir(parents=True, exist_ok=True)
        n_jobs = count_jobs(list(config.hydra.overrides.task))
        (sweep / PLAN_FILE).write_text(json.dumps({"n_jobs": n_jobs, "t0_unix_s": time.time()}))
        (sweep / LOG_FILE).touch()
        print(f"multirun: {n_jobs} jobs, progress in {sweep / LOG_FILE}", flush=True)

    def on_job_end(self, config: DictConfig, job_return: JobReturn, **kwargs: Any) -> None:
        try:
            from hydra.core.hydra_config import HydraConfig
            from hydra.types import RunMode

            if HydraConfig.get().mode != RunMode.MULTIRUN:
                return
        except ValueError:
            return
        sweep = _sweep_dir(config)
        try:
            plan = json.loads((sweep / PLAN_FILE).read_text())
        except (OSError, ValueError):
            return
        ok = job_return.status == JobStatus.COMPLETED
        value = job_return._return_value if ok else None
        record = {"job": int(config.hydra.job.num), "ok": ok,
                  "result": value if isinstance(value, dict) else None,
                  "error": None if ok else f"{type(job_return._return_value).__name__}: {job_return._return_value}"}
        with open(sweep / LOG_FILE, "a") as f:  # one short line per append: safe across processes
            f.write(json.dumps(record, default=str) + "\n")
        lines = [json.loads(ln) for ln in (sweep / LOG_FILE).read_text().splitlines() if ln.strip()]
        skipped = sum(1 for r in lines if (r.get("result") or {}).get("skipped"))
        meter = tqdm.format_meter(len(lines), plan["n_jobs"], time.time() - plan["t0_unix_s"], prefix="sweep",
                                  unit="trial", initial=skipped, ncols=100)
        summary = (record["result"] or {}).get("summary") or record["error"] or ""
        print(f"{meter}  {summary}", flush=True)

    def on_multirun_end(self, config: DictConfig, **kwargs: Any) -> None:
        path = _sweep_dir(config) / LOG_FILE
        if not path.exists():
            return
        lines = [json.loads(ln) for ln in path.read_text().splitlines() if ln.strip()]
        tally = Counter("failed" if not r["ok"] else "skipped" if (r.get("result") or {}).get("skipped")
                        else "ran" for r in lines)
        plan = json.loads((_sweep_dir(config) / PLAN_FILE).read_text())
        left = plan["n_jobs"] - len(lines)
        print(f"multirun done: {tally['ran']} ran, {tally['skipped']} already complete, {tally['failed']} failed"
              + (f", {left} not reported" if left else "")
              + f" ({math.ceil(time.time() - plan['t0_unix_s'])} s)", flush=True)
