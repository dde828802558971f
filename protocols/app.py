"""What both Hydra apps share: config checks before anything moves, the rig's life cycle, exit codes.

Exit codes: 0 done; 2 configuration refused (nothing connected, nothing written); 1 a device
error, a refused motion or a timeout stopped the run (motion stopped, trial file closed
"aborted: ..."), or a trial ran to its end with more lost skin frames than `max_lost_skin_frames`
allows (closed "incomplete: ...", kept as .partial; the run went on with the next trial); 130
Ctrl-C, 143 SIGTERM (same; SIGTERM is what SLURM and process managers send). Rerunning the same
command resumes. In a multirun a job that fails is recorded and the next one runs (`sweep_job`);
the command then exits 1.

Ctrl-C and SIGTERM take one path: the first asks the control loop to stop at its next tick (a
safe point); a second one, or for SIGTERM `STOP_GRACE_S` without a tick (a wait on a device, a
long computation), stops the run at once where it is. Either way the trial in progress is closed
"aborted". While the devices are still connecting no tick will come and no file is open: the first
signal stops the run at once. A run a signal stopped ends without the interpreter's teardown once
its files are closed (`layerskin_exp.cli.exit_now`), so SIGTERM ends it within a second.
"""

from __future__ import annotations

import contextlib
import gc
import logging
import signal
import sys
import threading
from collections.abc import Callable

from omegaconf import DictConfig, OmegaConf

from layerskin_exp.cli import EXIT_CONFIG, EXIT_INTERRUPTED, EXIT_TERMINATED, expand_sweep, one_line, refuse
from layerskin_exp.config import ConfigError, validate

__all__ = ["EXIT_CONFIG", "expand_sweep", "refuse_renamed", "refuse_shared_files",
           "run_app", "sweep_job"]

log = logging.getLogger(__name__)

EXIT_FAILED = 1
# SIGTERM has no second press: a request no control tick has acted on by then (three ticks at the
# slowest control_period_s) is acted on at once. A process manager follows SIGTERM with SIGKILL
# after a few seconds, which leaves no closed file.
STOP_GRACE_S = 0.3


def refuse_renamed(argv: list[str], renamed: dict[str, str]) -> None:
    """A key that was renamed (units now in its name): one line naming the new key, exit 2."""
    for a in argv:
        key, sep, value = a.partition("=")
        key = key.lstrip("+~")
        if sep and key in renamed:
            refuse(ConfigError(f"{key}={value}: renamed; use {renamed[key]}"))


def _changes_the_files(key: str) -> bool:
    """Whether an override of `key` can change which session files a job writes."""
    from protocols.identity import RUN_ONLY_KEYS

    if key == "data_root":
        return True
    if any(key == k or key.startswith(k + ".") for k in RUN_ONLY_KEYS):
        return False
    # device addresses, ports and timeouts say where the bench is, not what it does
    return not (key.startswith("hardware.") and key != "hardware.backend" and not key.startswith("hardware.faults"))


def refuse_shared_files(argv: list[str]) -> None:
    """A multirun whose jobs differ only in settings that do not change the data (save_images,
    estimator, progress, device addresses...) would have every job write the same session files:
    refused as a whole, one line, exit 2. Read from the overrides alone (nothing is composed)."""
    if not ("-m" in argv or "--multirun" in argv):
        return
    overrides = [a for a in argv if not a.startswith("-") and not a.split("=", 1)[0].lstrip("+~").startswith("hydra")]
    seen: dict[tuple, list[str]] = {}
    for job in expand_sweep(overrides):
        files = tuple(sorted(o for o in job if _changes_the_files(o.split("=", 1)[0].lstrip("+~"))))
        if files in seen:
            refuse(ConfigError(f"multirun: jobs '{' '.join(seen[files])}' and '{' '.join(job)}' would write the same "
                               "session files: they differ only in settings that do not change the data; run them "
                               "one after the other"))
        seen[files] = job


class JobFailed(SystemExit):
    """The run failed with exit code EXIT_FAILED; `reason` is the one line it printed."""

    def __init__(self, reason: str) -> None:
        super().__init__(EXIT_FAILED)
        self.reason = reason


def _fail(reason: str) -> None:
    print(f"error: {reason}", file=sys.stderr)
    raise JobFailed(reason)


def sweep_job(task: Callable[[], dict]) -> dict:
    """task() as one Hydra job. In a multirun a job that fails (a device error, a timeout, a
    refusal, an exception) returns {"failed": True, "error": ..., "exit_code": ...} instead of
    ending the sweep: the progress log records it, the next job runs, and the command exits
    non-zero after the summary (protocols.progress). Ctrl-C and SIGTERM still end the sweep."""
    from hydra.core.hydra_config import HydraConfig
    from hydra.types import RunMode

    if HydraConfig.get().mode != RunMode.MULTIRUN:
        return task()
    try:
        return task()
    except SystemExit as e:
        if e.code in (EXIT_INTERRUPTED, EXIT_TERMINATED):
            raise
        code = e.code
        reason = getattr(e, "reason", None) or ("configuration refused" if code == EXIT_CONFIG else f"exit {code}")
    except Exception as e:  # noqa: BLE001 - any failure of one job is that job's outcome
        log.exception("job failed")
        code, reason = EXIT_FAILED, f"{type(e).__name__}: {one_line(e)}"
        print(f"error: {reason}", file=sys.stderr)
    return {"failed": True, "error": reason, "exit_code": code, "summary": f"failed: {reason}"}


_grace: list[threading.Timer] = []
_holding: list[bool] = []  # the run has ended; the live view is held open (live_hold)
_connecting: list[bool] = []  # the devices are connecting: no control tick will come, no file is open


def _on_sigterm(signum, frame) -> None:
    """First SIGTERM: stop at the next tick; a second one, or STOP_GRACE_S without a tick: at once.
    While the devices connect: at once."""
    from protocols.runner import request_termination, terminate_now, termination_pending  # loaded by run_app

    if termination_pending() or _connecting:
        request_termination("terminated (SIGTERM)")
        terminate_now()
        return
    request_termination("terminated (SIGTERM)")
    # this handler again, through a real signal to the main thread: a blocking wait there returns
    timer = threading.Timer(STOP_GRACE_S, signal.pthread_kill, (threading.main_thread().ident, signal.SIGTERM))
    timer.daemon = True
    timer.start()
    _grace.append(timer)


def _on_sigint(signum, frame) -> None:
    """First Ctrl-C: stop at the next tick, closing the trial cleanly; a second one: at once.
    While the live view holds after the run: stop holding."""
    from protocols.runner import request_termination, terminate_now, termination_pending  # loaded by run_app

    if _holding:
        print("the run has already ended and its files are written; closing the live view", file=sys.stderr,
              flush=True)
        request_termination("interrupted (Ctrl-C)")
        return
    if termination_pending() or _connecting:
        request_termination("interrupted (Ctrl-C)")
        terminate_now()
        return
    request_termination("interrupted (Ctrl-C)")
    print("stopping at the next control tick (Ctrl-C again to stop at once)", file=sys.stderr, flush=True)


@contextlib.contextmanager
def _sigterm_as_exception():
    """Turn SIGTERM into `Terminated` raised by the control loop at its next tick while the rig
    runs (Hydra runs jobs in the main thread; elsewhere the default handling stays)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGTERM, _on_sigterm), signal.signal(signal.SIGINT, _on_sigint)
    try:
        yield
    finally:
        from protocols.runner import termination_pending  # loaded by run_app

        while _grace:
            _grace.pop().cancel()
        if termination_pending():
            # The run stopped on a signal and the process is on its way out: a further Ctrl-C (a
            # double press) or SIGTERM would only cut short what is left, closing devices and the
            # exit hooks (tqdm's among them), with a raw KeyboardInterrupt traceback or exit -2.
            previous = signal.SIG_IGN, signal.SIG_IGN
        signal.signal(signal.SIGTERM, previous[0])
        signal.signal(signal.SIGINT, previous[1])


def run_app(cfg: DictConfig, setup: str, body: Callable[[object, object, dict], object],
            prepare: Callable[[object], None] | None = None):
    """Validate, run prepare(typed_cfg) when given, build and connect the rig, run
    body(typed_cfg, rig, metadata), always stop and disconnect; a run that connected ends by
    printing where its session files went and how many it wrote (however it ended).

    Nothing moves before every device is connected and the config validated. Whatever a run
    would import or load lazily belongs before the devices connect (here or in `prepare`): an
    import holds the interpreter lock for much of its body, and the loopback emulators run in
    this process against 50 ms stream deadlines (tests/protocols/test_late_imports.py). The
    modules a run needs are imported here, not with this module: the command line's checks and
    `--help` import it too, and answer without them.
    """
    from tqdm.auto import tqdm

    from hardware import build_rig  # the backends import heavy optional drivers
    from hardware.interfaces import DeviceError
    from protocols.runner import RUN_FILES, winding_down

    RUN_FILES.reset()  # the jobs of a multirun may share this process
    winding_down(False)
    try:
        typed = validate(cfg)
        tqdm.get_lock()  # tqdm makes its lock, importing multiprocessing, at its first bar
        if prepare is not None:
            prepare(typed)
        rig = build_rig(cfg, setup)
    except ConfigError as e:
        refuse(e)
    except DeviceError as e:
        log.error("device error before connecting: %s", one_line(e))
        _fail(one_line(e))
    with _sigterm_as_exception():
        return _run_connected(cfg, setup, rig, typed, body)


def _run_connected(cfg: DictConfig, setup: str, rig, typed, body):
    from layerskin_exp.log import SessionInUseError
    from layerskin_exp.provenance import provenance
    from protocols.runner import (
        RUN_FILES,
        Terminated,
        TrialConflictError,
        check_termination,
        termination_pending,
        termination_reason,
        winding_down,
    )

    try:
        _connecting.append(True)
        try:
            rig.connect()
        finally:
            _connecting.clear()
    except (Terminated, KeyboardInterrupt, Exception) as e:  # noqa: BLE001 - any failure to connect ends the run
        rig.disconnect()
        if isinstance(e, Exception) and not termination_pending():
            _fail(f"could not connect the {rig.backend} rig: {one_line(e)}")
        # stopped while a device was still connecting (a signal raised inside a library's call may
        # come out as that library's error: an extension module's import gives ImportError)
        why = str(e) if isinstance(e, Terminated) else (termination_reason() or "interrupted (Ctrl-C)")
        print(f"{why} while connecting: nothing was recorded; rerun the same command to start", file=sys.stderr)
        sys.exit(EXIT_INTERRUPTED if "Ctrl-C" in why else EXIT_TERMINATED)
    sys.audit("layerskin_exp.rig_connected", rig.backend)  # from here on the devices stream
    if not rig.clock.is_virtual:
        # Everything built so far (modules, configs, drivers) leaves the garbage collector's reach:
        # a full collection stops every thread, and over this heap it took ~200 ms, which the
        # drivers' threads see as every stream stalling at once. Frozen, it takes milliseconds.
        gc.freeze()
    metadata = {"config": OmegaConf.to_container(cfg, resolve=True), "backend": rig.backend,
                "calibration": rig.skin.calibration(), "provenance": provenance()}
    camera = getattr(rig.camera, "calibration", None) if rig.camera is not None else None
    if camera is not None:
        metadata["camera"] = camera()
    prov = metadata["provenance"]
    log.info("layerskin-exp %s (commit %s%s) on the %s rig; overrides %s", prov["version"], prov["git_commit"],
             ", dirty" if prov["git_dirty"] else "", rig.backend, prov["overrides"])
    live = None
    if getattr(typed, "live", False):
        from layerskin_exp.log.view.live import LiveView

        allowed = {} if typed.live_allowed_hosts is None else {"allowed_hosts": typed.live_allowed_hosts}
        live = LiveView(setup, host=typed.live_host, port=typed.live_port, token=typed.live_token, **allowed)
        print(f"live view: open {live.url} in Foxglove (Open connection > Foxglove WebSocket)", flush=True)
    finished = False
    try:
        try:
            check_termination()  # SIGTERM while connecting
            result = body(typed, rig, metadata, **({"live": live} if live is not None else {}))
        finally:
            # ended, failed or stopped: a signal from here on does not cut the closing short
            winding_down()
        finished = True
        if RUN_FILES.incomplete:
            n = len(RUN_FILES.incomplete)
            _fail(f"{n} trial{'' if n == 1 else 's'} incomplete ({RUN_FILES.incomplete[0]}"
                  f"{'' if n == 1 else ', ...'}); kept as .mcap.partial, rerun the same command to record "
                  f"{'it' if n == 1 else 'them'} again")
        return result
    except KeyboardInterrupt:
        rig.stop_motion()
        print(f"interrupted: motion stopped, {RUN_FILES.stop_note()}; rerun the same command to resume",
              file=sys.stderr)
        sys.exit(EXIT_INTERRUPTED)
    except Terminated as e:
        rig.stop_motion()
        print(f"{e}: motion stopped, {RUN_FILES.stop_note()}; rerun the same command to resume", file=sys.stderr)
        sys.exit(EXIT_INTERRUPTED if "Ctrl-C" in str(e) else EXIT_TERMINATED)
    except ConfigError as e:
        rig.stop_motion()
        refuse(e)
    except TrialConflictError as e:  # a complete trial of another identity is in the way: left untouched
        rig.stop_motion()
        log.error("run refused: %s", one_line(e))
        _fail(one_line(e))
    except SessionInUseError as e:  # another run holds this trial's file: nothing was written here
        rig.stop_motion()
        log.error("run refused: %s", one_line(e))
        _fail(one_line(e))
    except Exception as e:
        rig.stop_motion()
        log.error("run stopped: %s: %s", type(e).__name__, one_line(e))
        _fail(f"{type(e).__name__}: {one_line(e)} (motion stopped, {RUN_FILES.stop_note()}; "
              "rerun the same command to resume)")
    finally:
        rig.stop_motion()
        rig.disconnect()
        print(RUN_FILES.line(), flush=True)
        if live is not None:
            if finished and getattr(typed, "live_hold", False):
                _holding.append(True)
                try:
                    live.hold(termination_pending)  # Ctrl-C or SIGTERM ends it
                finally:
                    _holding.clear()
            live.close()
