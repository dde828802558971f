"""A folder of sessions -> one LeRobot v3.0 dataset (one episode per complete trial).

The format follows huggingface/lerobot at commit 7427f31801f944f5ec9ce53cda02862ce7d1638b
(lerobot 0.6.2, CODEBASE_VERSION "v3.0"): src/lerobot/datasets/utils.py (paths, DatasetInfo,
chunk sizes), feature_utils.py (features -> parquet types), dataset_writer.py and
dataset_metadata.py (per-frame columns, episode metadata, tasks), compute_stats.py (stats,
see lerobot_stats.py), video_utils.py (the video info keys). Written with pyarrow and OpenCV:

    meta/info.json                         codebase_version, fps, features, totals, paths, splits,
                                           robot_type; and "resampling" (how the streams were put
                                           on the dataset's timeline; LeRobot ignores extra keys)
    meta/stats.json                        per feature: min, max, mean, std, count, q01..q99
    meta/tasks.parquet                     task (index) -> task_index
    meta/episodes/chunk-000/file-000.parquet   one row per episode: episode_index, tasks, length,
                                           data/..., dataset_from/to_index, videos/<key>/...,
                                           stats/<feature>/<stat>, meta/episodes/..., and ours:
                                           labels/<label> (the trial's labels), source (the file)
    meta/layerskin_export.json             which session became which episode, what was left out
    data/chunk-000/file-000.parquet        one row per frame, one row group per episode
    videos/observation.images.camera/chunk-000/file-000.mp4   where the camera's images were logged

Timeline: frame k of an episode covers the period [t0 + k/fps, t0 + (k+1)/fps) of the trial's
host timeline (Session.streams[...]["t_ns"]), t0 the latest first sample of the streams
exported, as many whole periods as fit before the earliest last sample. Skin layers and the
wrench: the mean of the samples in the period (a block mean; at the default rate about five skin
frames, the study's downsampling); a period with no sample holds the latest earlier one. Poses,
gripper, stage, markers, camera: the latest sample at or before the period's end (what was
known when the period closed). timestamp = k / fps exactly, as LeRobot's writer stores it.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from layerskin_exp.log.errors import SessionFileError
from layerskin_exp.log.export import lerobot_stats as ST
from layerskin_exp.log.session.reader import Session, load_session

LEROBOT_COMMIT = "7427f31801f944f5ec9ce53cda02862ce7d1638b"
LEROBOT_VERSION = "0.6.2"
CODEBASE_VERSION = "v3.0"
CHUNKS_SIZE = 1000  # DEFAULT_CHUNK_SIZE: files per chunk folder
DATA_FILES_SIZE_IN_MB = 100
VIDEO_FILES_SIZE_IN_MB = 200
CHUNK_FILE = "chunk-{chunk_index:03d}/file-{file_index:03d}"
DATA_PATH = "data/" + CHUNK_FILE + ".parquet"
VIDEO_PATH = "videos/{video_key}/" + CHUNK_FILE + ".mp4"
EPISODES_PATH = "meta/episodes/" + CHUNK_FILE + ".parquet"
TASKS_PATH = "meta/tasks.parquet"
TOLERANCE_S = 1e-4  # LeRobotDataset(tolerance_s=1e-4): timestamps within this of k / fps
DOWNSAMPLE = 5  # the study's block mean (layerskin_exp.estimation.config.PreprocessConfig.downsample)
EXPORT_RECORD = "meta/layerskin_export.json"

DEFAULT_FEATURES = {
    "timestamp": {"dtype": "float32", "shape": [1], "names": None},
    "frame_index": {"dtype": "int64", "shape": [1], "names": None},
    "episode_index": {"dtype": "int64", "shape": [1], "names": None},
    "index": {"dtype": "int64", "shape": [1], "names": None},
    "task_index": {"dtype": "int64", "shape": [1], "names": None},
}

TASKS = {
    "force_calibration": "Press, then slide, a 2.5 mm spherical indenter on the two-layer skin with the "
                         "three-axis platform; the F/T sensor under the skin gives the reference force",
    "grip_depth": "Close the Robotiq Hand-E with the two-layer skin on a jaw to the grip depth, then move "
                  "the gripped object with the UR5e",
}
ROBOT_TYPES = {"force_calibration": "three_axis_platform", "grip_depth": "ur5e_robotiq_hand_e"}

SKIN_NAMES = ["row", "column"]
POSE_NAMES = ["x_m", "y_m", "z_m", "qx", "qy", "qz", "qw"]
GRIPPER_FIELDS = ["position_mm", "requested_mm", "speed", "force", "object_detected", "fault"]
CAMERA_KEY = "observation.images.camera"
MEAN, LATEST = "mean", "latest"


class ExportError(ValueError):
    """Bad input to the export (the message is one line naming the value and what to do)."""


@dataclass(frozen=True)
class LeftOut:
    path: str
    reason: str


@dataclass
class ExportReport:
    out: Path
    fps: int
    episodes: list[str] = field(default_factory=list)  # source session of each episode, in order
    frames: int = 0
    left_out: list[LeftOut] = field(default_factory=list)
    features: list[str] = field(default_factory=list)
    features_dropped: dict[str, list[str]] = field(default_factory=dict)  # feature -> sessions lacking it

    def describe(self) -> str:
        lines = [f"{self.out}: LeRobot {CODEBASE_VERSION} dataset, {len(self.episodes)} episode(s), "
                 f"{self.frames} frames at {self.fps} fps",
                 f"  features: {', '.join(self.features)}"]
        for key, lacking in self.features_dropped.items():
            lines.append(f"  not exported: {key} (absent from {len(lacking)} session(s), e.g. {lacking[0]})")
        if self.left_out:
            lines.append(f"  left out {len(self.left_out)} session(s), not exported:")
            lines += [f"    {x.path}: {x.reason}" for x in self.left_out]
        return "\n".join(lines)


@dataclass
class _Feature:
    key: str
    dtype: str
    shape: tuple
    names: list | None
    stream: str
    method: str
    marker_id: int | None = None

    def spec(self) -> dict:
        return {"dtype": self.dtype, "shape": list(self.shape), "names": self.names}


def _pyarrow():
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        raise ExportError("export lerobot needs pyarrow, which is not installed: "
                          "pip install 'layerskin-exp[lerobot]' (or pip install pyarrow)") from None
    return pa, pq


# ------------------------------------------------------------------------------ the sessions


def find_sessions(sessions) -> tuple[Path, list[Path], list[Path]]:
    """(root, finished .mcap files, .mcap.partial files) under `sessions` (a folder, searched
    recursively, or one .mcap file)."""
    root = Path(sessions)
    if not root.exists():
        raise ExportError(f"SESSIONS={str(sessions)!r} does not exist: give a folder of session files "
                          f"(e.g. data/force_calibration/<design>) or one .mcap file")
    if root.is_file():
        if not root.name.endswith((".mcap", ".mcap.partial")):
            raise ExportError(f"SESSIONS={str(sessions)!r} is a file but not a session (.mcap): give a folder "
                              f"of session files or one .mcap file")
        partial = root.name.endswith(".partial")
        return root.parent, [] if partial else [root], [root] if partial else []
    finals = sorted(p for p in root.rglob("*.mcap") if p.is_file())
    partials = sorted(p for p in root.rglob("*.mcap.partial") if p.is_file())
    if not finals and not partials:
        raise ExportError(f"SESSIONS={str(sessions)!r} holds no session files (*.mcap, searched recursively): "
                          f"give the folder a campaign or a multirun wrote")
    return root, finals, partials


@dataclass
class _Probe:
    path: Path
    streams: set[str]
    marker_ids: set[int]
    skin_period_ns: float
    protocol: str


def _why_not_complete(s: Session) -> str:
    parts = []
    if s.outcome is None:
        parts.append("not closed by its writer (no outcome recorded: cut off, a crash or a kill?)")
    elif not (s.outcome == "complete" or s.outcome.startswith("complete (")):
        parts.append(f"outcome {s.outcome!r}")
    if s.damaged:
        known = [x for x in s.lost if x.messages is not None]
        n = sum(sum(x.messages.values()) for x in known)
        lost = f"{n} message(s) lost" + (" and an unknown number more" if len(known) < len(s.lost) else "")
        parts.append(f"damaged ({len(s.lost)} lost range(s), {lost}"
                     + (f"; metadata {', '.join(s.damaged_fields)}" if s.damaged_fields else "") + ")")
    return "; ".join(parts) or "not complete"


def _probe(path: Path) -> _Probe | str:
    """What the first pass needs of a session, or why it is left out."""
    from layerskin_exp.log.container.scan import scan

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            s = load_session(path, streams={"skin", "markers"}, warn=False)
            names = {m.channel.metadata.get("stream") for m in scan(path).messages.values() if m.count}
    except (SessionFileError, OSError) as exc:
        return f"unreadable ({exc})"
    if not s.complete:
        return _why_not_complete(s)
    skin = s.streams.get("skin")
    if skin is None or len(skin["t_ns"]) < 2:
        return "no skin frames (or one): nothing to put on the dataset's timeline"
    markers = s.streams.get("markers")
    ids = set(np.unique(markers["marker_id"]).tolist()) if markers is not None and len(markers["t_ns"]) else set()
    protocol = s.labels.get("protocol") or s.metadata.get("protocol") or "unknown"
    return _Probe(path, {n for n in names if n}, ids, float(np.median(np.diff(skin["t_ns"]))), str(protocol))


def _features_of(probe: _Probe) -> list[_Feature]:
    f = [_Feature("observation.tactile.superficial", "float32", (16, 16), SKIN_NAMES, "skin", MEAN),
         _Feature("observation.tactile.deep", "float32", (16, 16), SKIN_NAMES, "skin", MEAN)]
    if "wrench" in probe.streams:
        f.append(_Feature("observation.wrench", "float32", (6,),
                          ["fx_n", "fy_n", "fz_n", "tx_nm", "ty_nm", "tz_nm"], "wrench", MEAN))
    if "stage" in probe.streams:
        f.append(_Feature("observation.stage.position", "float32", (3,), ["x_mm", "y_mm", "z_mm"], "stage", LATEST))
    if "tcp" in probe.streams:
        f.append(_Feature("observation.tcp.pose", "float32", (7,), POSE_NAMES, "tcp", LATEST))
    if "gripper" in probe.streams:
        f.append(_Feature("observation.gripper", "float32", (6,), GRIPPER_FIELDS, "gripper", LATEST))
    for mid in sorted(probe.marker_ids):
        f.append(_Feature(f"observation.markers.{mid}.pose", "float32", (7,), POSE_NAMES, "markers", LATEST, mid))
        f.append(_Feature(f"observation.markers.{mid}.age_s", "float32", (1,), None, "markers", LATEST, mid))
    if "camera" in probe.streams:
        f.append(_Feature(CAMERA_KEY, "video", (0, 0, 3), ["height", "width", "channels"], "camera", LATEST))
    return f


# ------------------------------------------------------------------------------ resampling


def _source(s: Session, ft: _Feature) -> tuple[np.ndarray, object]:
    """(t_ns, values) of one feature's samples in a session, values (n, *shape) (the camera: the
    image array or list, (n, H, W) uint8)."""
    a = s.streams[ft.stream]
    if ft.stream == "skin":
        return a["t_ns"], a[ft.key.rsplit(".", 1)[1]]
    if ft.stream == "wrench":
        return a["t_ns"], np.hstack([a["force_n"], a["torque_nm"]])
    if ft.stream == "stage":
        return a["t_ns"], a["position_mm"]
    if ft.stream == "tcp":
        return a["t_ns"], np.hstack([a["position_m"], a["orientation_xyzw"]])
    if ft.stream == "gripper":
        return a["t_ns"], np.column_stack([np.asarray(a[k], np.float64) for k in GRIPPER_FIELDS])
    if ft.stream == "markers":
        sel = a["marker_id"] == ft.marker_id
        return a["t_ns"][sel], np.hstack([a["position_m"][sel], a["orientation_xyzw"][sel]])
    return a["t_ns"], a["image"]


def _edges(t0: int, n: int, fps: int) -> np.ndarray:
    """n + 1 period edges (ns) from t0: t0 + round(k * 1e9 / fps)."""
    return t0 + np.round(np.arange(n + 1) * (1e9 / fps)).astype(np.int64)


def _block_mean(t: np.ndarray, v: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Mean of the samples in each [edges[k], edges[k+1]); an empty period holds the latest
    sample before its end."""
    flat = v.reshape(len(v), -1).astype(np.float64)
    cs = np.vstack([np.zeros((1, flat.shape[1])), np.cumsum(flat, axis=0)])
    idx = np.searchsorted(t, edges, side="left")
    lo, hi = idx[:-1], idx[1:]
    count = (hi - lo)[:, None]
    held = flat[np.maximum(hi - 1, 0)]
    mean = np.divide(cs[hi] - cs[lo], count, out=held.copy(), where=count > 0)
    return mean.reshape(len(edges) - 1, *v.shape[1:])


def _latest_index(t: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Index of the latest sample at or before each period's end."""
    return np.searchsorted(t, edges[1:], side="right") - 1


# ------------------------------------------------------------------------------ writing


def _arrow_column(pa, values: np.ndarray, shape: tuple):
    """A parquet column as LeRobot's features give it (feature_utils.get_hf_features_from_features):
    (1,) a scalar Value, (n,) a fixed-size list (datasets List(length=n)), (h, w) nested lists
    (the storage of datasets Array2D)."""
    if tuple(shape) == (1,):
        return pa.array(values.reshape(-1))
    if len(shape) == 1:
        return pa.FixedSizeListArray.from_arrays(pa.array(values.reshape(-1)), shape[0])
    n, h, w = values.shape
    inner = pa.ListArray.from_arrays(pa.array(np.arange(0, n * h * w + 1, w, dtype=np.int32)),
                                     pa.array(values.reshape(-1)))
    outer = pa.ListArray.from_arrays(pa.array(np.arange(0, n * h + 1, h, dtype=np.int32)), inner)
    return pa.ExtensionArray.from_storage(_array_type(pa, shape, str(values.dtype)), outer)


_EXT_TYPES: dict = {}


def _array_type(pa, shape: tuple, dtype: str):
    """datasets' ArrayND extension type (features.Array2DExtensionType ...): nested lists of the
    values, named and described as `datasets` does, so its reader gets the Array2D back."""
    if "cls" not in _EXT_TYPES:
        class ArrayXD(pa.ExtensionType):
            def __init__(self, shape, dtype):
                self.shape, self.value_type = tuple(shape), dtype
                storage = pa.from_numpy_dtype(np.dtype(dtype))
                for _ in shape:
                    storage = pa.list_(storage)
                pa.ExtensionType.__init__(self, storage,
                                          f"datasets.features.features.Array{len(shape)}DExtensionType")

            def __arrow_ext_serialize__(self):
                return json.dumps((self.shape, self.value_type)).encode()

            @classmethod
            def __arrow_ext_deserialize__(cls, storage_type, serialized):
                return cls(*json.loads(serialized))

        _EXT_TYPES["cls"] = ArrayXD
    return _EXT_TYPES["cls"](shape, dtype)


def _hf_feature(spec: dict) -> dict:
    """The `datasets` feature (Features.to_dict form) LeRobot declares for a feature."""
    shape = tuple(spec["shape"])
    value = {"dtype": spec["dtype"], "_type": "Value"}
    if shape == (1,):
        return value
    if len(shape) == 1:
        return {"feature": value, "length": shape[0], "_type": "List"}
    return {"shape": list(shape), "dtype": spec["dtype"], "_type": f"Array{len(shape)}D"}


def _arrow_type(pa, spec: dict, *, storage: bool = False):
    """The parquet type of a feature's column (storage: of the extension type's storage)."""
    shape, t = tuple(spec["shape"]), pa.from_numpy_dtype(np.dtype(spec["dtype"]))
    if shape == (1,):
        return t
    if len(shape) == 1:
        return pa.list_(t, shape[0])
    return _array_type(pa, shape, spec["dtype"]).storage_type if storage else _array_type(pa, shape, spec["dtype"])


def _tasks_table(pa, tasks: list[str]):
    """meta/tasks.parquet as LeRobot writes it (pandas DataFrame, index "task", column task_index)."""
    pandas_meta = {
        "index_columns": ["task"],
        "column_indexes": [{"name": None, "field_name": None, "pandas_type": "unicode", "numpy_type": "object",
                            "metadata": {"encoding": "UTF-8"}}],
        "columns": [{"name": "task_index", "field_name": "task_index", "pandas_type": "int64",
                     "numpy_type": "int64", "metadata": None},
                    {"name": "task", "field_name": "task", "pandas_type": "unicode", "numpy_type": "object",
                     "metadata": None}],
        "creator": {"library": "pyarrow", "version": pa.__version__},
        "pandas_version": "2.2.0",
    }
    schema = pa.schema([("task_index", pa.int64()), ("task", pa.string())],
                       metadata={b"pandas": json.dumps(pandas_meta).encode()})
    return pa.table({"task_index": pa.array(range(len(tasks)), pa.int64()), "task": pa.array(tasks, pa.string())},
                    schema=schema)


class _Video:
    """One video feature's mp4 files: episodes appended to the open file until it passes the
    size limit (as LeRobot concatenates them), frames written as they are resampled."""

    def __init__(self, root: Path, key: str, fps: int, limit_mb: float):
        self.root, self.key, self.fps, self.limit = root, key, fps, limit_mb * 1024 * 1024
        self.chunk = self.file = 0
        self.writer = None
        self.path: Path | None = None
        self.frames_in_file = 0
        self.shape: tuple | None = None

    def _open(self):
        self.path = self.root / VIDEO_PATH.format(video_key=self.key, chunk_index=self.chunk, file_index=self.file)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        h, w = self.shape
        self.writer = cv2.VideoWriter(str(self.path), cv2.VideoWriter_fourcc(*"mp4v"), float(self.fps), (w, h), True)
        if not self.writer.isOpened():
            raise ExportError(f"OpenCV cannot write an mp4 video ({self.path}): its build lacks the mp4v encoder")
        self.frames_in_file = 0

    def append(self, images, index: np.ndarray) -> dict:
        """Write frames images[index[k]]; the episode's videos/<key>/... metadata."""
        if self.writer is None:
            self._open()
        elif self.path.stat().st_size >= self.limit:
            self.writer.release()
            self.chunk, self.file = (self.chunk + 1, 0) if self.file == CHUNKS_SIZE - 1 else (self.chunk, self.file + 1)
            self._open()
        start = self.frames_in_file
        last, bgr = None, None
        for i in index.tolist():
            if i != last:
                img = images[i]
                bgr = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR) if img.ndim == 2 else img
                last = i
            self.writer.write(bgr)
        self.frames_in_file += len(index)
        return {f"videos/{self.key}/chunk_index": self.chunk, f"videos/{self.key}/file_index": self.file,
                f"videos/{self.key}/from_timestamp": start / self.fps,
                f"videos/{self.key}/to_timestamp": self.frames_in_file / self.fps}

    def close(self):
        if self.writer is not None:
            self.writer.release()
            self.writer = None


def _rgb(img: np.ndarray) -> np.ndarray:
    return np.repeat(img[..., None], 3, axis=2) if img.ndim == 2 else cv2.cvtColor(img, cv2.COLOR_BGR2RGB)


def _labels_columns(pa, rows: list[dict]) -> dict:
    """labels/<key> columns from the episodes' labels: typed where pyarrow can type them, else JSON."""
    keys = []
    for r in rows:
        keys += [k for k in r if k not in keys]
    cols = {}
    for k in keys:
        vals = [r.get(k) for r in rows]
        try:
            cols[f"labels/{k}"] = pa.array(vals)
        except (pa.ArrowInvalid, pa.ArrowTypeError, TypeError):
            cols[f"labels/{k}"] = pa.array([None if v is None else json.dumps(v) for v in vals], pa.string())
    return cols


# ------------------------------------------------------------------------------ the export


def _check_out(out: Path) -> None:
    if out.exists() and not out.is_dir():
        raise ExportError(f"OUT={str(out)!r} is a file: give a new (or empty) folder for the dataset")
    if out.is_dir() and any(out.iterdir()):
        raise ExportError(f"OUT={str(out)!r} exists and is not empty: give a new folder, or remove this one "
                          f"to export again")
    if not out.parent.exists():
        raise ExportError(f"OUT={str(out)!r}: its parent folder {str(out.parent)!r} does not exist; create it "
                          f"first")


def export_lerobot(sessions, out, *, fps: int | None = None) -> ExportReport:
    """Write the complete trials under `sessions` (a folder, searched recursively, or one .mcap)
    as one LeRobot v3.0 dataset in the new folder `out` (it may exist if empty).

    fps: the dataset's frame rate (an int, as LeRobot's info.json has it); default the skin's
    frame rate divided by the study's five-sample downsampling, rounded (85 for the study's
    2.36 ms frame period). Sessions that are damaged, cut off, not closed by their writer,
    incomplete or aborted, or have no skin frames, are left out and listed in the report (and in
    meta/layerskin_export.json). Raises ExportError (one line) for bad input.
    """
    if fps is not None and (isinstance(fps, bool) or not isinstance(fps, int) or fps <= 0):
        raise ExportError(f"fps={fps!r}: the dataset's frame rate must be a whole number of frames per second "
                          f"> 0 (LeRobot stores an int), e.g. --fps 30")
    out = Path(out)
    _check_out(out)
    root, finals, partials = find_sessions(sessions)
    pa, pq = _pyarrow()
    rel = (lambda p: str(p.relative_to(root))) if root.is_dir() else (lambda p: p.name)
    left_out = [LeftOut(rel(p), "interrupted (.mcap.partial: its writer did not finish it)") for p in partials]
    probes = []
    for p in finals:
        r = _probe(p)
        if isinstance(r, str):
            left_out.append(LeftOut(rel(p), r))
        else:
            probes.append(r)
    if not probes:
        raise ExportError(f"SESSIONS={str(sessions)!r}: none of its {len(finals) + len(partials)} session file(s) "
                          f"is a complete trial ({left_out[0].path}: {left_out[0].reason}); nothing to export")
    skin_rate = 1e9 / float(np.median([p.skin_period_ns for p in probes]))
    if fps is None:
        fps = max(1, round(skin_rate / DOWNSAMPLE))

    # Features: those every exported session has (a dataset has one set); the rest are listed.
    per = {p.path: {f.key: f for f in _features_of(p)} for p in probes}
    order = []
    for p in probes:
        order += [k for k in per[p.path] if k not in order]
    keys = [k for k in order if all(k in per[p.path] for p in probes)]
    dropped = {k: [rel(p.path) for p in probes if k not in per[p.path]] for k in order if k not in keys}
    features = [per[probes[0].path][k] for k in keys]
    protocols = sorted({p.protocol for p in probes})
    tasks = [TASKS.get(proto, f"{proto} trial") for proto in protocols]

    tmp = out.parent / f".{out.name}.partial-{os.getpid()}"
    if tmp.exists():
        shutil.rmtree(tmp)
    tmp.mkdir()
    try:
        report = _write(pa, pq, tmp, probes, features, fps, skin_rate, tasks, protocols, rel, left_out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    if out.is_dir():
        out.rmdir()
    tmp.rename(out)
    report.out = out
    report.features_dropped = dropped
    record = json.loads((out / EXPORT_RECORD).read_text())
    record["features_dropped"] = dropped
    (out / EXPORT_RECORD).write_text(json.dumps(record, indent=2))
    return report


def _write(pa, pq, root: Path, probes, features, fps, skin_rate, tasks, protocols, rel, left_out) -> ExportReport:
    video = _Video(root, CAMERA_KEY, fps, VIDEO_FILES_SIZE_IN_MB) if any(f.dtype == "video" for f in features) else None
    data_feats = [f for f in features if f.dtype != "video"]
    specs = {f.key: f.spec() for f in features}
    schema_fields = [(f.key, _arrow_type(pa, f.spec())) for f in data_feats]
    schema_fields += [(k, _arrow_type(pa, v)) for k, v in DEFAULT_FEATURES.items()]
    hf = {f.key: _hf_feature(f.spec()) for f in data_feats} | {k: _hf_feature(v) for k, v in DEFAULT_FEATURES.items()}
    schema = pa.schema(schema_fields, metadata={b"huggingface": json.dumps({"info": {"features": hf}}).encode()})
    limit = DATA_FILES_SIZE_IN_MB * 1024 * 1024
    chunk = file = 0
    writer, file_bytes = None, 0
    episodes, all_stats, sources, label_rows = [], [], [], []
    total = 0
    camera_shape = None
    for probe in probes:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            s = load_session(probe.path, streams={f.stream for f in features}, warn=False)
        src = {f.key: _source(s, f) for f in features}
        t0 = max(int(t[0]) for t, _ in src.values() if len(t))
        t1 = min(int(t[-1]) for t, _ in src.values() if len(t))
        if any(len(t) == 0 for t, _ in src.values()):
            left_out.append(LeftOut(rel(probe.path), "a stream the dataset's features need holds no samples"))
            continue
        n = int(math.floor((t1 - t0) * fps / 1e9))
        if n < 1:
            left_out.append(LeftOut(rel(probe.path), f"its streams overlap for {(t1 - t0) / 1e9:.3f} s, less than "
                                                     f"one frame at {fps} fps"))
            continue
        edges = _edges(t0, n, fps)
        cols, cam_index = {}, None
        for f in features:
            t, v = src[f.key]
            if f.dtype == "video":
                cam_index = _latest_index(t, edges)
                shape = tuple(np.asarray(v[0]).shape[:2])
                if camera_shape is None:
                    camera_shape = shape
                elif shape != camera_shape:
                    cam_index = None
                    break
            elif f.key.endswith(".age_s"):
                j = _latest_index(t, edges)
                cols[f.key] = ((edges[1:] - t[j]) / 1e9).astype(np.float32)
            elif f.method == MEAN:
                cols[f.key] = _block_mean(t, v, edges).astype(np.float32)
            else:
                cols[f.key] = np.asarray(v, np.float64)[_latest_index(t, edges)].astype(np.float32)
        if video is not None and cam_index is None:
            left_out.append(LeftOut(rel(probe.path), f"camera images of another size than the first episode's "
                                                     f"{camera_shape}"))
            continue
        ep = len(episodes)
        protocol = probe.protocol
        task_index = protocols.index(protocol)
        frame_index = np.arange(n, dtype=np.int64)
        cols["timestamp"] = (frame_index / fps).astype(np.float32)
        cols["frame_index"] = frame_index
        cols["episode_index"] = np.full(n, ep, np.int64)
        cols["index"] = np.arange(total, total + n, dtype=np.int64)
        cols["task_index"] = np.full(n, task_index, np.int64)

        stats = {k: ST.vector_stats(v) for k, v in cols.items()}
        table = pa.Table.from_arrays([_arrow_column(pa, cols[name], specs.get(name, DEFAULT_FEATURES.get(name))["shape"])
                                      for name, _ in schema_fields], schema=schema)
        if writer is not None and file_bytes + table.nbytes >= limit:
            writer.close()
            writer, file_bytes = None, 0
            chunk, file = (chunk + 1, 0) if file == CHUNKS_SIZE - 1 else (chunk, file + 1)
        if writer is None:
            path = root / DATA_PATH.format(chunk_index=chunk, file_index=file)
            path.parent.mkdir(parents=True, exist_ok=True)
            writer = pq.ParquetWriter(str(path), schema, compression="snappy", use_dictionary=True)
        writer.write_table(table)  # one row group per episode
        file_bytes += table.nbytes
        meta = {"episode_index": ep, "tasks": [tasks[task_index]], "length": n,
                "data/chunk_index": chunk, "data/file_index": file,
                "dataset_from_index": total, "dataset_to_index": total + n}
        if video is not None:
            images = src[CAMERA_KEY][1]
            video.shape = camera_shape
            meta.update(video.append(images, cam_index))
            sample = ST.sample_indices(n)
            stats[CAMERA_KEY] = ST.image_stats(np.stack([_rgb(np.asarray(images[cam_index[i]])) for i in sample]))
        episodes.append(meta)
        all_stats.append(stats)
        sources.append(rel(probe.path))
        label_rows.append(dict(s.labels))
        total += n
    if writer is not None:
        writer.close()
    if video is not None:
        video.close()
    if not episodes:
        raise ExportError(f"no session could be exported ({left_out[-1].path}: {left_out[-1].reason})")

    if video is not None:
        h, w = camera_shape
        specs[CAMERA_KEY] = {"dtype": "video", "shape": [h, w, 3], "names": ["height", "width", "channels"],
                             "info": {"video.height": h, "video.width": w, "video.codec": "mpeg4",
                                      "video.pix_fmt": "yuv420p", "video.fps": fps,
                                      "video.channels": 3, "has_audio": False, "is_depth_map": False}}
    feature_specs = {**specs, **DEFAULT_FEATURES}
    _write_episodes(pa, pq, root, episodes, all_stats, sources, label_rows, feature_specs)
    pq.write_table(_tasks_table(pa, tasks), str(root / TASKS_PATH))
    stats = ST.aggregate(all_stats)
    (root / "meta" / "stats.json").write_text(json.dumps(ST.to_json(stats), indent=4))
    info = {
        "codebase_version": CODEBASE_VERSION,
        "fps": fps,
        "features": feature_specs,
        "total_episodes": len(episodes),
        "total_frames": total,
        "total_tasks": len(tasks),
        "chunks_size": CHUNKS_SIZE,
        "data_files_size_in_mb": DATA_FILES_SIZE_IN_MB,
        "video_files_size_in_mb": VIDEO_FILES_SIZE_IN_MB,
        "data_path": DATA_PATH,
        "video_path": VIDEO_PATH if video is not None else None,
        "robot_type": ROBOT_TYPES.get(protocols[0]) if len(protocols) == 1 else None,
        "splits": {"train": f"0:{len(episodes)}"},
        "resampling": _resampling(features, fps, skin_rate),
    }
    (root / "meta" / "info.json").write_text(json.dumps(info, indent=4))
    report = ExportReport(root, fps, sources, total, left_out, list(feature_specs))
    record = {"exporter": "layerskin_exp.log.export.lerobot", "lerobot_reference": {
        "repository": "huggingface/lerobot", "commit": LEROBOT_COMMIT, "version": LEROBOT_VERSION},
        "episodes": [{"episode_index": i, "source": src, "labels": lab}
                     for i, (src, lab) in enumerate(zip(sources, label_rows, strict=True))],
        "left_out": [{"path": x.path, "reason": x.reason} for x in left_out]}
    (root / EXPORT_RECORD).write_text(json.dumps(record, indent=2))
    return report


def _resampling(features, fps: int, skin_rate: float) -> dict:
    methods = {}
    for f in features:
        if f.method == MEAN:
            methods[f.key] = (f"mean of the {f.stream} samples in each frame period "
                              f"[t0 + k/fps, t0 + (k+1)/fps); a period with none holds the latest earlier sample")
        elif f.key.endswith(".age_s"):
            methods[f.key] = "seconds from the marker's latest detection to the frame period's end"
        else:
            methods[f.key] = f"latest {f.stream} sample at or before the frame period's end (t0 + (k+1)/fps)"
    return {
        "fps": fps,
        "default_fps": "skin frame rate / 5 (the study's five-sample downsampling), rounded",
        "skin_rate_hz": round(skin_rate, 3),
        "skin_samples_per_frame": round(skin_rate / fps, 3),
        "timeline": "each session's host timeline (t_ns); t0 = the latest first sample of the exported "
                    "streams; whole frame periods until the earliest last sample; timestamp = k / fps",
        "methods": methods,
    }


def _write_episodes(pa, pq, root: Path, episodes, all_stats, sources, label_rows, feature_specs) -> None:
    """meta/episodes/chunk-000/file-000.parquet: LeRobot's columns (dataset_metadata.save_episode,
    flatten_dict({"stats": ...}) with "/"), then labels/<key> and source."""
    cols: dict[str, list] = {}
    for meta, stats in zip(episodes, all_stats, strict=True):
        row = dict(meta)
        for key in feature_specs:
            if key in stats:
                for stat, v in stats[key].items():
                    row[f"stats/{key}/{stat}"] = np.asarray(v).tolist()
        row["meta/episodes/chunk_index"] = 0
        row["meta/episodes/file_index"] = 0
        for k, v in row.items():
            cols.setdefault(k, []).append(v)
    table = pa.Table.from_pydict(cols)
    for k, v in _labels_columns(pa, label_rows).items():
        table = table.append_column(k, v)
    table = table.append_column("source", pa.array(sources, pa.string()))
    path = root / EPISODES_PATH.format(chunk_index=0, file_index=0)
    path.parent.mkdir(parents=True, exist_ok=True)
    pq.write_table(table, str(path), compression="snappy")
