"""Progress across a Hydra multirun, where each job is one trial.

A Hydra callback (configured under `hydra.callbacks` in both primary configs): at the start of a
multirun it counts the jobs and notes the start time in the sweep folder; after each job (in
whatever process or node ran it) it appends the job's result to `sweep_progress.jsonl` there and
prints one progress line (done/left, ETA) plus the trial summary; at the end it prints a tally
and each failed job's overrides and reason, and ends the command with exit 1 if any job failed or
never reported (a failing job does not stop the others: protocols.app.sweep_job records its failure).
Works the same with the basic, joblib and SLURM launchers (the sweep folder is shared). Each
multirun has its own id in the plan, so a reused sweep folder (the same sweep run again) counts
only this run's jobs, each once: no negative "not reported", no bar past its total.
"""

from __future__ import annotations

import json
import math
import os
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


def _this_run(sweep: Path, run_id: str) -> dict[int, dict]:
    """job number -> its latest record in this multirun. The log is append-only and a sweep folder
    may be reused (a rerun of the same sweep): other runs' lines and a job reported twice count once."""
    jobs: dict[int, dict] = {}
    try:
        text = (sweep / LOG_FILE).read_text()
    except OSError:
        return jobs
    for ln in text.splitlines():
        try:
            r = json.loads(ln)
        except ValueError:
            continue  # a line cut by a crash
        if isinstance(r, dict) and r.get("run") == run_id:
            jobs[int(r.get("job", -1))] = r
    return jobs


def _tally(jobs: dict[int, dict]) -> Counter:
    return Counter("failed" if not r.get("ok") else "skipped" if (r.get("result") or {}).get("skipped") else "ran"
                   for r in jobs.values())


class SweepProgress(Callback):
    def on_multirun_start(self, config: DictConfig, **kwargs: Any) -> None:
        sweep = _sweep_dir(config)
        sweep.mkdir(parents=True, exist_ok=True)
        n_jobs = count_jobs(list(config.hydra.overrides.task))
        run_id = f"{time.time_ns()}-{os.getpid()}"
        (sweep / PLAN_FILE).write_text(json.dumps({"n_jobs": n_jobs, "t0_unix_s": time.time(), "run": run_id}))
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
        completed = job_return.status == JobStatus.COMPLETED
        value = job_return._return_value if completed else None
        value = value if isinstance(value, dict) else None
        ok = completed and not (value or {}).get("failed")  # a failed job returns its failure (sweep_job)
        error = None if ok else (value or {}).get("error") or \
            f"{type(job_return._return_value).__name__}: {job_return._return_value}"
        record = {"run": plan.get("run"), "job": int(config.hydra.job.num), "ok": ok,
                  "overrides": list(config.hydra.overrides.task), "result": value, "error": error}
        with open(sweep / LOG_FILE, "a") as f:  # one short line per append: safe across processes
            f.write(json.dumps(record, default=str) + "\n")
        jobs = _this_run(sweep, plan.get("run"))
        done = len(jobs)
        skipped = _tally(jobs)["skipped"]
        # the plan's count comes from the command line; should Hydra launch more, the bar grows with it
        meter = tqdm.format_meter(done, max(plan["n_jobs"], done), time.time() - plan["t0_unix_s"], prefix="sweep",
                                  unit="trial", initial=min(skipped, done), ncols=100)
        summary = (record["result"] or {}).get("summary") or record["error"] or ""
        print(f"{meter}  {summary}", flush=True)

    def on_multirun_end(self, config: DictConfig, **kwargs: Any) -> None:
        sweep = _sweep_dir(config)
        try:
            plan = json.loads((sweep / PLAN_FILE).read_text())
        except (OSError, ValueError):
            return
        jobs = _this_run(sweep, plan.get("run"))
        tally = _tally(jobs)
        left = max(0, plan["n_jobs"] - len(jobs))
        print(f"multirun done: {tally['ran']} ran, {tally['skipped']} already complete, {tally['failed']} failed"
              + (f", {left} not reported" if left else "")
              + f" ({math.ceil(time.time() - plan['t0_unix_s'])} s)", flush=True)
        failed = [r for _, r in sorted(jobs.items()) if not r.get("ok")]
        for r in failed:
            print(f"  failed: job {r.get('job')} ({' '.join(r.get('overrides') or [])}): {r.get('error')}", flush=True)
        # Hydra would exit 0: the command's status says a job failed, or never reported (killed)
        if failed or left:
            raise SystemExit(1)
