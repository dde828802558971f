"""From session files to analysis arrays: discovery, per-trial preprocessing, references.

Every trial is reduced as soon as it is read (smoothed and downsampled maps, references on the
downsampled skin timeline), so a whole campaign fits in memory.
"""

from __future__ import annotations

import hashlib
import json
import multiprocessing
import os
import warnings
from collections import Counter
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from itertools import repeat
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

from analysis.config import PreprocessConfig
from layerskin_exp.log import SessionFileError
from layerskin_exp.log.container.scan import special_file_kind


@dataclass
class CalibrationTrial:
    """maps (K, 2, 16, 16) counts above baseline; force_n (K, 3); t_s (K,)."""

    name: str
    labels: dict
    t_s: np.ndarray
    maps: np.ndarray
    force_n: np.ndarray
    identity: str = ""
    stream_health: dict | None = None  # the drivers' counters over the trial (Session.stream_health)


@dataclass
class GripTrial:
    """A grip trial restricted to its motion phase, on the downsampled skin timeline.

    arm_ref, vision_ref (K,): mm (translation) or ° (torsion) relative to the motion start
    (NaN where the stream is absent). vision_t_s / vision_sig: the vision reference on the
    camera's own timeline (for slip ground truth).
    """

    name: str
    labels: dict
    t_s: np.ndarray
    maps: np.ndarray
    arm_ref: np.ndarray
    vision_ref: np.ndarray
    vision_t_s: np.ndarray
    vision_sig: np.ndarray
    identity: str = ""
    stream_health: dict | None = None  # the drivers' counters over the trial (Session.stream_health)

    @property
    def grip_depth_mm(self) -> float:
        return float(self.labels["grip_depth_mm"])

    @property
    def motion(self) -> str:
        return str(self.labels["motion"])


@dataclass
class Skipped:
    """A file the analysis did not use: a short reason (counted) and the detail (reported)."""

    name: str
    reason: str
    detail: str = ""

    def __post_init__(self) -> None:  # names and reader messages as the report prints them
        self.name, self.detail = shown(self.name), shown(self.detail)


@dataclass
class Campaign:
    """skipped: reason -> count; skipped_files: every file not used, by name, with the detail
    (the reader's error, the damage, the trial it duplicates)."""

    calibration: list[CalibrationTrial] = field(default_factory=list)
    grip: list[GripTrial] = field(default_factory=list)
    skipped: Counter = field(default_factory=Counter)
    skipped_files: list[Skipped] = field(default_factory=list)
    n_files: int = 0


def shown(name) -> str:
    """A file name as the report prints it: bytes that are not UTF-8 (kept by the file system as
    surrogate escapes) written as \\xNN, so any terminal, report.md and results.json take it."""
    return os.fsencode(str(name)).decode("utf-8", "backslashreplace")


def sessions_problem(sessions) -> str:
    """Why `sessions=` cannot be read ('' if it can): a folder of .mcap files, or one .mcap file."""
    p = Path(sessions)
    kind = special_file_kind(p)
    if kind is not None:
        return f"sessions={shown(p)}: a {kind}, not a folder or a .mcap file; point sessions= at a folder of .mcap files"
    if not p.exists():
        return (f"sessions={shown(p)}: no such file or folder; point sessions= at a folder of .mcap files or one "
                ".mcap file")
    if p.is_file() and p.suffix != ".mcap":
        return f"sessions={p}: a file that is not a .mcap session; point sessions= at a folder or a .mcap file"
    if not os.access(p, os.R_OK):
        return f"sessions={p}: not readable (permissions)"
    return ""


def discover(root) -> tuple[list[Path], list[Skipped]]:
    """Every *.mcap regular file under root, recursively (not through links to folders, as
    rglob), sorted; root itself if it is a .mcap file. Also what was left out on the way, each with
    why: a folder that could not be listed (permissions, a vanished mount), a special file named
    *.mcap (a FIFO, socket or device: told by type, never opened, since reading a FIFO blocks)."""
    root = Path(root)
    problem = sessions_problem(root)
    if problem:
        raise FileNotFoundError(problem)
    if root.is_file():
        return [root], []
    found: list[Path] = []
    left_out: list[Skipped] = []
    folders = [root]
    while folders:
        folder = folders.pop()
        try:
            with os.scandir(folder) as it:
                entries = list(it)
        except OSError as exc:
            left_out.append(Skipped(f"{folder.relative_to(root)}/", "folder not read",
                                    f"{exc.strerror or exc}; its session files are not in the report"))
            continue
        for entry in entries:
            path = Path(entry.path)
            try:
                is_dir = entry.is_dir(follow_symlinks=False)
            except OSError:
                is_dir = False
            if is_dir:
                folders.append(path)
                if entry.name.endswith(".mcap"):  # named like a session: reported as not one
                    found.append(path)
            elif entry.name.endswith(".mcap"):
                kind = special_file_kind(path)
                if kind is None:
                    found.append(path)
                else:
                    left_out.append(Skipped(str(path.relative_to(root)), "not a regular file",
                                            f"a {kind}; skipped without opening it"))
    return sorted(found), sorted(left_out, key=lambda f: f.name)


def trial_identity(metadata: dict, labels: dict) -> str:
    """What makes two files the same trial: metadata["identity"] when the protocol stored one,
    else the protocol, the labels and a hash of the resolved config."""
    if metadata.get("identity"):
        return f"identity:{metadata['identity']}"
    config = json.dumps(metadata.get("config", {}), sort_keys=True, default=str)
    return "|".join((
        str(labels.get("protocol")),
        json.dumps(labels, sort_keys=True, default=str),
        hashlib.sha256(config.encode()).hexdigest()[:16],
    ))


def _skin_counts(skin: dict) -> np.ndarray:
    return np.stack([skin["superficial"], skin["deep"]], axis=1)  # (N, 2, 16, 16)


def _interp_rows(t_new, t, v) -> np.ndarray:
    """Linear interpolation of each column of v (N, D) at t_new."""
    return np.column_stack([np.interp(t_new, t, v[:, i]) for i in range(v.shape[1])])


def _motion_window(events: dict | None, t0: float, t1: float) -> tuple[float, float]:
    """[start, end] s of the 'motion' phase (to the next phase event), else the whole trial."""
    if not events or not len(events.get("kind", [])):
        return t0, t1
    t = np.asarray(events["t_ns"]) / 1e9
    phases = [(ti, m) for ti, k, m in zip(t, events["kind"], events["message"], strict=False) if k == "phase"]
    for i, (ti, m) in enumerate(phases):
        if m == "motion":
            end = phases[i + 1][0] if i + 1 < len(phases) else t1
            return float(ti), float(end)
    return t0, t1


def _reference(t_s, positions, quats, motion):
    from analysis.tracking import (  # scikit-learn: not for a config check
        torsion_reference_deg,
        translation_reference_mm,
    )

    return translation_reference_mm(positions) if motion == "translation" else torsion_reference_deg(quats)


def _vision(markers: dict | None, window, motion) -> tuple[np.ndarray, np.ndarray, list]:
    """Per-marker vision references in the window: (t_s of the best-seen marker, its signal, all
    markers as (t_s, signal) pairs)."""
    if not markers or not len(markers.get("marker_id", [])):
        return np.zeros(0), np.zeros(0), []
    t = np.asarray(markers["t_ns"]) / 1e9
    ids = np.asarray(markers["marker_id"])
    per = []
    for mid in np.unique(ids):
        m = (ids == mid) & (t >= window[0]) & (t <= window[1])
        if m.sum() < 2:
            continue
        per.append((t[m], _reference(t[m], markers["position_m"][m], markers["orientation_xyzw"][m], motion)))
    if not per:
        return np.zeros(0), np.zeros(0), []
    best = max(per, key=lambda p: p[0].size)
    return best[0], best[1], per


def _calibration_trial(s, name, pp: PreprocessConfig) -> CalibrationTrial | str:
    from layerskin_exp.estimation.preprocess import preprocess_counts, smooth_downsample  # scikit-learn

    if "wrench" not in s.streams or not len(s.streams["wrench"]["t_ns"]):
        return "calibration trial without wrench stream"
    skin = s.streams["skin"]
    counts = _skin_counts(skin)
    t_raw = skin["t_ns"].astype(np.float64) / 1e9
    w = s.streams["wrench"]
    force = _interp_rows(t_raw, w["t_ns"].astype(np.float64) / 1e9, np.asarray(w["force_n"], np.float64))
    return CalibrationTrial(
        name=name, labels=dict(s.labels),
        t_s=smooth_downsample(t_raw, pp.ma_window, pp.downsample),
        maps=preprocess_counts(counts, pp.ma_window, pp.downsample, pp.baseline_frames),
        force_n=smooth_downsample(force, pp.ma_window, pp.downsample).astype(np.float32))


def _grip_trial(s, name, pp: PreprocessConfig) -> GripTrial | str:
    from layerskin_exp.estimation.preprocess import preprocess_counts, smooth_downsample  # scikit-learn

    motion = s.labels.get("motion")
    if motion not in ("translation", "torsion"):
        return f"grip trial with unknown motion {motion!r}"
    skin = s.streams["skin"]
    counts = _skin_counts(skin)
    t_raw = skin["t_ns"].astype(np.float64) / 1e9
    t_s = smooth_downsample(t_raw, pp.ma_window, pp.downsample)
    maps = preprocess_counts(counts, pp.ma_window, pp.downsample, pp.baseline_frames)
    win = _motion_window(s.streams.get("events"), t_s[0], t_s[-1])
    keep = (t_s >= win[0]) & (t_s <= win[1])
    if keep.sum() < 10:
        return "grip trial with fewer than 10 frames in its motion phase"
    t_s, maps = t_s[keep], maps[keep]
    arm = np.full(t_s.size, np.nan)
    tcp = s.streams.get("tcp")
    if tcp is not None and len(tcp["t_ns"]):
        tt = tcp["t_ns"] / 1e9
        m = (tt >= win[0]) & (tt <= win[1])
        if m.sum() >= 2:
            arm = np.interp(t_s, tt[m], _reference(tt[m], tcp["position_m"][m], tcp["orientation_xyzw"][m], motion))
    vt, vsig, per = _vision(s.streams.get("markers"), win, motion)
    vision = (np.mean([np.interp(t_s, a, b) for a, b in per], axis=0) if per else np.full(t_s.size, np.nan))
    return GripTrial(name=name, labels=dict(s.labels), t_s=t_s, maps=maps, arm_ref=arm, vision_ref=vision,
                     vision_t_s=vt, vision_sig=vsig)


# What the analysis reads (calibration: skin, wrench; grip: skin, tcp, markers, events): the
# stage, gripper and camera streams are not decoded.
STREAMS = ("skin", "wrench", "tcp", "markers", "events")


def load_trial(path, root, pp: PreprocessConfig) -> CalibrationTrial | GripTrial | Skipped:
    """Read one session file and reduce it to a trial, or say why it is skipped. Never raises on
    a bad file: one bad input must not stop a whole report."""
    from layerskin_exp.log import SessionWarning, load_session

    path = Path(path)
    root = Path(root)
    name = shown(path.relative_to(root if root.is_dir() else root.parent))
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", SessionWarning)
            s = load_session(path, streams=STREAMS, warn=False)
    except SessionFileError as exc:
        return Skipped(name, "unreadable file", str(exc))
    if s.damaged:
        lost = "; ".join(x.describe() for x in s.lost[:3]) or "; ".join(s.warnings[:2])
        return Skipped(name, "damaged file", f"{s.chunks_skipped} chunk(s) skipped: {lost}")
    if not s.complete:
        return Skipped(name, "outcome not complete", f"outcome {s.outcome!r}")
    skin = s.streams.get("skin")
    if skin is None or len(skin["t_ns"]) < 2 * pp.downsample + pp.ma_window:
        return Skipped(name, "no or too short skin stream")
    proto = s.labels.get("protocol")
    try:
        if proto == "force_calibration":
            trial = _calibration_trial(s, name, pp)
        elif proto == "grip_depth":
            trial = _grip_trial(s, name, pp)
        else:
            return Skipped(name, f"unknown protocol {proto!r}")
    except Exception as exc:  # noqa: BLE001 - the report carries on without this trial, saying why
        return Skipped(name, "cannot be analysed", f"{type(exc).__name__}: {exc}")
    if isinstance(trial, str):
        return Skipped(name, trial)
    trial.identity = trial_identity(s.metadata, s.labels)
    trial.stream_health = s.stream_health
    return trial


def idle_cores() -> int:
    """Cores this process may use that are not already busy (1-minute load average, this process
    counted as one), at least 1."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    try:
        busy = max(0.0, os.getloadavg()[0] - 1.0)
    except OSError:
        busy = 0.0
    return max(1, min(cores, int(cores - busy + 0.5)))


def _pool_workers(workers: int | None, n_files: int) -> int:
    # A worker costs a fresh interpreter (~1.5 s CPU of imports) and pickled trials: only worth it
    # with idle cores and enough files. Measured on 2 cores already shared with ~4 busy processes,
    # 2 workers took 1.9x the serial CPU time on 100 calibration files and twice the wall time.
    if workers is None:
        return max(1, min(idle_cores(), n_files // 16))
    return max(1, min(workers, n_files))


def load_campaign(root, pp: PreprocessConfig | None = None, progress: bool = True,
                  workers: int | None = None) -> Campaign:
    """Read and reduce every complete session under root (a folder, or one .mcap file); count
    what was skipped and why, and name each skipped file. A trial present more than once (a
    copy in another folder) is used once: the first in sorted order; the others are skipped as
    duplicates (see trial_identity).

    workers: processes reading files in parallel (None: one per idle core, see idle_cores; 1: in
    this process). Trials keep the sorted file order whatever the number of workers.
    """
    pp = pp or PreprocessConfig()
    root = Path(root)
    paths, left_out = discover(root)
    camp = Campaign(n_files=len(paths) + sum(f.reason == "not a regular file" for f in left_out))
    for f in left_out:
        camp.skipped[f.reason] += 1
        camp.skipped_files.append(f)
    n_workers = _pool_workers(workers, len(paths))
    bar = tqdm(total=len(paths), desc="sessions", leave=False, disable=not progress)
    if n_workers == 1:
        results = (load_trial(p, root, pp) for p in paths)
        pool = None
    else:
        # spawn, not fork: the parent may hold torch/OpenMP threads that a forked child would inherit.
        pool = ProcessPoolExecutor(n_workers, mp_context=multiprocessing.get_context("spawn"))
        results = pool.map(load_trial, paths, repeat(root), repeat(pp), chunksize=4)
    seen: dict[str, str] = {}
    try:
        for trial in results:
            bar.update()
            if not isinstance(trial, Skipped) and trial.identity in seen:
                trial = Skipped(trial.name, "duplicate trial", f"same trial as {seen[trial.identity]}")
            if isinstance(trial, Skipped):
                camp.skipped[trial.reason] += 1
                camp.skipped_files.append(trial)
                continue
            seen[trial.identity] = trial.name
            if isinstance(trial, CalibrationTrial):
                camp.calibration.append(trial)
            else:
                camp.grip.append(trial)
    finally:
        bar.close()
        if pool is not None:
            pool.shutdown(cancel_futures=True)
    return camp
