"""Load a LeRobot dataset with lerobot's own LeRobotDataset and dump what it gives back as JSON.

Run by tools/lerobot_load_check.py with the Python of its separate venv (the one with the
`lerobot` release); it imports nothing of this project. Offline: HF_HUB_OFFLINE=1 and
HF_DATASETS_OFFLINE=1 are set before lerobot is imported, and every socket connect and name
lookup is refused and recorded, so a load that reaches for the hub fails and says so.

    python tools/lerobot_load_probe.py DATASET OUT.json
"""

from __future__ import annotations

import json
import os
import socket
import sys
from importlib import metadata
from pathlib import Path

NETWORK_ATTEMPTS: list[str] = []


def _block_network() -> None:
    os.environ["HF_HUB_OFFLINE"] = "1"
    os.environ["HF_DATASETS_OFFLINE"] = "1"

    def refuse(what):
        def f(*args, **kwargs):
            NETWORK_ATTEMPTS.append(f"{what}{args[1:2] if what == 'connect' else args[:2]}")
            raise OSError(f"lerobot_load_probe: network refused ({what})")
        return f

    socket.socket.connect = refuse("connect")
    socket.socket.connect_ex = refuse("connect")
    socket.getaddrinfo = refuse("getaddrinfo")
    socket.create_connection = refuse("create_connection")


def _version(dist: str) -> str | None:
    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return None


def _plain(v):
    """A tensor / array / scalar -> JSON (nested lists of numbers, or a string)."""
    if hasattr(v, "detach"):
        v = v.detach().cpu().numpy()
    if hasattr(v, "tolist"):
        return v.tolist()
    return v


def _video_frames(path: Path) -> int:
    import av

    with av.open(str(path)) as c:
        return sum(1 for _ in c.decode(video=0))


def main(argv: list[str]) -> int:
    root, out = Path(argv[0]).resolve(), Path(argv[1])
    _block_network()
    import torch  # noqa: F401  (before lerobot: its version goes in the record)
    from lerobot.datasets.lerobot_dataset import CODEBASE_VERSION, LeRobotDataset

    ds = LeRobotDataset("layerskin/check", root=root)  # a local root: no hub access is needed
    meta = ds.meta
    episodes = []
    for e in meta.episodes:
        row = {k: e[k] for k in ("episode_index", "length", "dataset_from_index", "dataset_to_index")}
        row["tasks"] = list(e["tasks"])
        row["source"] = e.get("source")
        for key in meta.video_keys:
            row[key] = {k: e[f"videos/{key}/{k}"] for k in ("chunk_index", "file_index", "from_timestamp",
                                                           "to_timestamp")}
        episodes.append(row)
    picks = sorted({i for e in episodes for i in (e["dataset_from_index"],
                                                  (e["dataset_from_index"] + e["dataset_to_index"]) // 2,
                                                  e["dataset_to_index"] - 1)})
    items, item_errors, video_error = {}, {}, None
    for i in picks:
        try:
            try:
                item = ds[i]
            except (AttributeError, ImportError, RuntimeError) as exc:
                if not meta.video_keys:
                    raise
                # No video decoder here (reported): lerobot's own parquet loading and torch
                # transform, without the video frames.
                video_error = f"{type(exc).__name__}: {exc}"
                item = ds.hf_dataset[i]
        except Exception as exc:  # noqa: BLE001 - an item LeRobot cannot give is a failed comparison
            item_errors[str(i)] = f"{type(exc).__name__}: {exc}"
            continue
        items[str(i)] = {k: (_plain(v) if k not in meta.video_keys else list(v.shape))
                         for k, v in item.items()}
    videos = {}
    for key in meta.video_keys:
        files = sorted({(e[key]["chunk_index"], e[key]["file_index"]) for e in episodes})
        for c, f in files:
            p = root / meta.video_path.format(video_key=key, chunk_index=c, file_index=f)
            videos[str(p.relative_to(root))] = _video_frames(p)
    import torchvision

    record = {
        "versions": {"lerobot": _version("lerobot"), "codebase_version": CODEBASE_VERSION,
                     "torch": _version("torch"), "torchvision": getattr(torchvision, "__version__", None),
                     "torchvision_stub": bool(getattr(torchvision, "LAYERSKIN_STUB", False)),
                     "datasets": _version("datasets"), "huggingface_hub": _version("huggingface-hub"),
                     "pyarrow": _version("pyarrow"), "av": _version("av"), "python": sys.version.split()[0]},
        "video_backend": ds.video_backend,
        "num_frames": ds.num_frames, "num_episodes": ds.num_episodes, "fps": ds.fps, "len": len(ds),
        "hf_rows": len(ds.hf_dataset),
        "features": {k: {"dtype": v["dtype"], "shape": list(v["shape"])} for k, v in ds.features.items()},
        "video_keys": list(meta.video_keys),
        "tasks": meta.tasks.index.tolist(),
        "episodes": episodes,
        "items": items,
        "item_errors": item_errors,
        "video_decode_error": video_error,
        "video_frames": videos,
        "network_attempts": NETWORK_ATTEMPTS,
    }
    out.write_text(json.dumps(record))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
