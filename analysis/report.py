"""`python -m analysis.report [sessions=DIR] out=DIR [analysis=demo|default|paper] [sensitivity=FILE]`

Turns a folder of session files into the study's tables and figures, ours beside the study's:
out/results.json, out/predictions.npz, out/report.md, out/config.yaml (the resolved config), out/*.png,
out/models/*.pt (estimator artifacts:
each carries the preprocessing from raw counts with the model; T-s5.pt also the causal slip detector,
ready for OnlineEstimator.from_artifact and `python -m layerskin_exp.estimation.export`).
The estimators come from layerskin_exp.estimation; this module orchestrates them and writes tables.
A missing input (no calibration campaign, no shear trials, no grip sessions, no markers) skips
the sections that need it with the reason in results.json and report.md. `sensitivity=FILE` (a
`python -m protocols.sensitivity out=FILE` result) adds the simulator's bands over its brackets to
the characterisation section; a missing or unreadable file is refused before anything runs.
`sessions=` defaults to `data`, where the protocols write; a folder without a session file is
refused (exit 2), naming it.
"""

from __future__ import annotations

import errno
import logging
import os
import sys
import time
from contextlib import contextmanager
from pathlib import Path

from omegaconf import DictConfig

from analysis.config import AnalysisConfig, ReportConfig
from analysis.markdown import counted
from analysis.report_run import ReportRun
from analysis.sessions import sessions_problem
from layerskin_exp.cli import EXIT_CONFIG, hydra_main, override_values, refuse, run_command
from layerskin_exp.config import SkinConfig, validate
from layerskin_exp.provenance import provenance

log = logging.getLogger(__name__)
# The analysis stack (torch, scikit-learn, the sections) loads when a report runs, not for --help
# or a refused command line (benchmarks/cli_help).


class Analysis(ReportRun):
    """One report run: loads the sessions, runs the sections (analysis.sections: force,
    characterisation, tracking, slip) in order, writes results.json and report.md. Sections fill
    self.results and leave what later ones need on it (ts5, calib_feats); figures go to self.out."""

    def load(self) -> None:
        from analysis.sections import streams as streams_section

        super().load()
        streams_section.stream_health(self)

    def force(self) -> None:
        from analysis.sections import force as force_section

        force_section.force(self)

    def characterization(self) -> None:
        from analysis.sections import characterisation as characterisation_section

        characterisation_section.characterization(self)

    def tracking(self) -> None:
        from analysis.sections import tracking as tracking_section

        tracking_section.tracking(self)

    def slip(self) -> None:
        from analysis.sections import slip as slip_section

        slip_section.slip(self)

    def run(self) -> dict:
        from layerskin_exp.estimation.cnn import default_torch_threads

        self.out.mkdir(parents=True, exist_ok=True)
        with deterministic_torch(self.a.cnn.torch_threads or default_torch_threads(self.a.cnn.device)):
            return self._run()

    def _run(self) -> dict:
        self.results["provenance"] = {**provenance(), "analysis_preset": self.preset, "config_file": "config.yaml"}
        log.info("report %s -> %s (analysis preset %s, layerskin-exp %s, commit %s%s)", self.cfg.sessions, self.out,
                 self.preset, self.results["provenance"]["version"], self.results["provenance"]["git_commit"],
                 ", dirty" if self.results["provenance"]["git_dirty"] else "")
        stages = [("load sessions", self.load), ("force estimation", self.force),
                  ("characterisation", self.characterization), ("tracking", self.tracking),
                  ("slip detection", self.slip), ("write report", self.write)]
        from tqdm.auto import tqdm

        bar = tqdm(stages, desc="report", disable=not self.a.progress)
        for name, fn in bar:
            bar.set_postfix_str(name)
            t0 = time.perf_counter()
            log.info("stage: %s", name)
            fn()
            self.results["timing_s"][name] = time.perf_counter() - t0
            log.info("stage %s done in %.1f s", name, self.results["timing_s"][name])
        return self.results


@contextmanager
def deterministic_torch(threads: int):
    """Torch settings under which a report re-run on the same sessions gives the same numbers.

    Seeds alone are not enough on a GPU: the training step gathers shared frame encodings by
    index, whose backward pass accumulates with atomic adds in whatever order the threads finish,
    and cuDNN may pick non-deterministic convolution algorithms. The T-s5 model then differs in
    its last bits from run to run, and the cues built on its force (f_xyz, f_z, the preload, the
    live detector) move in the third decimal. Deterministic kernels cost little for this model.
    The intra-op thread count is fixed too: CPU reductions split by thread. Restored on exit."""
    import torch

    os.environ.setdefault("CUBLAS_WORKSPACE_CONFIG", ":4096:8")  # deterministic cuBLAS (read at first use)
    saved = (torch.get_num_threads(), torch.are_deterministic_algorithms_enabled(),
             torch.backends.cudnn.deterministic, torch.backends.cudnn.benchmark)
    torch.set_num_threads(threads)
    torch.use_deterministic_algorithms(True, warn_only=True)  # warn, not fail, on an op without one
    torch.backends.cudnn.deterministic, torch.backends.cudnn.benchmark = True, False
    try:
        yield
    finally:
        torch.set_num_threads(saved[0])
        torch.use_deterministic_algorithms(saved[1])
        torch.backends.cudnn.deterministic, torch.backends.cudnn.benchmark = saved[2], saved[3]


def run_report(sessions, out, analysis: AnalysisConfig | None = None, skin: SkinConfig | None = None,
               preset: str | None = None, sensitivity=None) -> dict:
    """Library entry point: the same as the command line. preset: a name for the record (report.md,
    results.json); the config itself is `analysis`. sensitivity: a screening result file (ConfigError
    before anything runs when it cannot be read)."""
    return Analysis(ReportConfig(sessions=str(sessions), out=str(out), analysis=analysis or AnalysisConfig(),
                                 skin=skin or SkinConfig(),
                                 sensitivity=None if sensitivity is None else str(sensitivity)), preset).run()


def _hydra_preset() -> str | None:
    """The analysis preset chosen for this Hydra run (analysis=demo|default|paper)."""
    from hydra.core.hydra_config import HydraConfig

    return HydraConfig.get().runtime.choices.get("analysis") if HydraConfig.initialized() else None


def _sessions_problem(sessions) -> str:
    """Why the command line cannot report `sessions=` ('' if it can): unreadable, or a folder with
    no session file under it (the library's run_report still writes a report of nothing)."""
    problem = sessions_problem(sessions)
    p = Path(sessions)
    if not problem and p.is_dir() and next(p.rglob("*.mcap"), None) is None:
        problem = (f"sessions={sessions}: no session files (*.mcap) under {p.resolve()}; point sessions= at the "
                   "data_root a protocol wrote to (default data)")
    return problem


def _out_problem(out) -> str:
    """Why out= cannot hold the report ('' if it can); creates the folder."""
    try:
        Path(out).mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        return f"out={out}: exists and is not a folder; point out= at a folder for the report"
    except OSError as exc:
        return f"out={out}: cannot create the report folder ({exc.strerror or exc})"
    if not os.access(out, os.W_OK):
        return f"out={out}: not writable"
    return ""


@hydra_main("report")
def main(cfg: DictConfig) -> None:
    try:
        rc: ReportConfig = validate(cfg)
    except ValueError as e:
        refuse(e)
    problem = _sessions_problem(rc.sessions) or _out_problem(rc.out)
    if problem:
        print(f"error: {problem}", file=sys.stderr)
        sys.exit(EXIT_CONFIG)
    try:
        res = Analysis(rc, _hydra_preset()).run()
    except OSError as e:
        if e.errno not in DISK_FULL:
            raise
        where = f": {e.filename}" if e.filename else ""
        print(f"error: out={rc.out}: the report could not be written ({e.strerror or e}{where}); free space "
              "there or point out= at another disk", file=sys.stderr)
        sys.exit(1)
    print(f"report written to {Path(rc.out) / 'report.md'} ({counted(len(res['skipped']), 'section')} skipped)")


# A disk that takes no more: full, over quota, too large a file, read-only (out= and its job log).
DISK_FULL = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EROFS)


def _check_command_line(argv: list[str]) -> None:
    """sessions=/out= given on the command line are checked before Hydra starts (Hydra makes
    its run folder under out= first and would fail there with a traceback), as Hydra reads them
    (a quoted path with spaces without its quotes); a command line Hydra cannot parse is refused
    first, before out= is made."""
    values = override_values(argv)
    for key, check in (("sessions", _sessions_problem), ("out", _out_problem)):
        problem = check(values[key]) if key in values else ""
        if problem:
            print(f"error: {problem}", file=sys.stderr)
            sys.exit(EXIT_CONFIG)


if __name__ == "__main__":  # as the console script (analysis.cli.report), with this module loaded
    run_command("report", lambda: main, before=[_check_command_line])
