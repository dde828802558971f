"""meta/stats.json as LeRobot computes it, without LeRobot (it needs a torch we cannot install).

Follows src/lerobot/datasets/compute_stats.py of huggingface/lerobot at commit
7427f31801f944f5ec9ce53cda02862ce7d1638b (lerobot 0.6.2, dataset format v3.0), re-implemented
here with numpy alone:

- per episode (compute_episode_stats): every numeric feature, the five per-frame columns
  (timestamp, frame_index, episode_index, index, task_index) included, reduced over axis 0;
  LeRobot's running statistics flatten every axis but the last, so a (16, 16) feature gets
  statistics of shape (16,) (one per column over rows and frames) and a (1,) feature stored as
  (N,) gets shape (1,). Images and videos: a sample of the episode's frames (sample_indices),
  shrunk to about 150 px (auto_downsample_height_width), per channel, divided by 255, shape
  (C, 1, 1). Each has min, max, mean, std (population), count (frames) and the quantiles
  q01, q10, q50, q90, q99 from a 5000-bin histogram (RunningQuantileStats).
- over the dataset (aggregate_stats): min of mins, max of maxes, count-weighted mean, the
  parallel-variance std, and for quantiles the conservative envelope (min for q <= 50, max above).
"""

from __future__ import annotations

import numpy as np

DEFAULT_QUANTILES = (0.01, 0.10, 0.50, 0.90, 0.99)
QUANTILE_KEYS = tuple(f"q{int(q * 100):02d}" for q in DEFAULT_QUANTILES)
NUM_BINS = 5000


def _running_stats(batch: np.ndarray) -> dict[str, np.ndarray]:
    """RunningQuantileStats after one update with `batch` (rows x vector length), then
    get_statistics(); one update is all compute_episode_stats makes per episode."""
    batch = batch.reshape(-1, batch.shape[-1])
    batch = batch.astype(np.result_type(batch.dtype, np.float32), copy=False)
    n = batch.shape[0]
    lo, hi = np.min(batch, axis=0), np.max(batch, axis=0)
    mean = np.mean(batch, axis=0)  # in the batch's float type (float32 for float32 and uint16 data)
    mean_sq = np.mean(batch**2, axis=0)
    std = np.sqrt(np.maximum(0, mean_sq - mean**2))
    out = {"min": lo.copy(), "max": hi.copy(), "mean": mean, "std": std, "count": np.array([n])}
    quants = [[] for _ in DEFAULT_QUANTILES]
    for i in range(batch.shape[1]):
        edges = np.linspace(lo[i] - 1e-10, hi[i] + 1e-10, NUM_BINS + 1)
        hist, _ = np.histogram(batch[:, i], bins=edges)
        cumsum = np.cumsum(hist.astype(np.float64))
        for j, q in enumerate(DEFAULT_QUANTILES):
            quants[j].append(_quantile(cumsum, edges, q * n))
    for key, vals in zip(QUANTILE_KEYS, quants, strict=True):
        out[key] = np.array(vals)
    return out


def _quantile(cumsum: np.ndarray, edges: np.ndarray, target: float) -> float:
    """RunningQuantileStats._compute_single_quantile: linear interpolation within the bin."""
    idx = int(np.searchsorted(cumsum, target))
    if idx == 0:
        return edges[0]
    if idx >= len(cumsum):
        return edges[-1]
    before = cumsum[idx - 1]
    in_bin = cumsum[idx] - before
    if in_bin == 0:
        return edges[idx]
    return edges[idx] + (target - before) / in_bin * (edges[idx + 1] - edges[idx])


def _basic_stats(array: np.ndarray, count: int) -> dict[str, np.ndarray]:
    """_compute_basic_stats: fewer than two rows; quantiles are the mean."""
    out = {"min": np.min(array, axis=0), "max": np.max(array, axis=0), "mean": np.mean(array, axis=0),
           "std": np.std(array, axis=0), "count": np.array([count])}
    for key in QUANTILE_KEYS:
        out[key] = out["mean"].copy()
    return out


def vector_stats(data: np.ndarray) -> dict[str, np.ndarray]:
    """get_feature_stats(data, axis=0, keepdims=data.ndim == 1) of one episode's column."""
    reshaped = data.reshape(-1, 1) if data.ndim == 1 else data
    if reshaped.shape[0] < 2:
        stats = _basic_stats(reshaped, data.shape[0])
    else:
        stats = _running_stats(reshaped)
        stats["count"] = np.array([data.shape[0]])
    if data.ndim == 1:  # keepdims: (1,) statistics
        stats = {k: v if k == "count" else np.asarray(v).reshape(1) for k, v in stats.items()}
    return stats


def sample_indices(n: int) -> list[int]:
    """compute_stats.sample_indices / estimate_num_samples (min 100, max 10000, power 0.75)."""
    num = min(100, n)
    num = max(num, min(int(n**0.75), 10_000))
    return np.round(np.linspace(0, n - 1, num)).astype(int).tolist()


def _downsample(img: np.ndarray, target: int = 150, threshold: int = 300) -> np.ndarray:
    """auto_downsample_height_width of a (C, H, W) image."""
    _, h, w = img.shape
    if max(w, h) < threshold:
        return img
    factor = int(w / target) if w > h else int(h / target)
    return img[:, ::factor, ::factor]


def image_stats(frames_hwc: np.ndarray) -> dict[str, np.ndarray]:
    """Stats of a video feature from one episode's (N, H, W, C) uint8 frames, as LeRobot
    computes them from the frames it encodes: (C, 1, 1) per channel in [0, 1]."""
    idx = sample_indices(len(frames_hwc))
    imgs = np.stack([_downsample(np.transpose(frames_hwc[i], (2, 0, 1))) for i in idx])
    b, c, h, w = imgs.shape
    flat = imgs.transpose(0, 2, 3, 1).reshape(-1, c)
    stats = _running_stats(flat) if flat.shape[0] >= 2 else _basic_stats(flat, b)
    stats["count"] = np.array([b])
    return {k: v if k == "count" else np.asarray(v).reshape(c, 1, 1) / 255.0 for k, v in stats.items()}


def aggregate(stats_list: list[dict[str, dict[str, np.ndarray]]]) -> dict[str, dict[str, np.ndarray]]:
    """aggregate_stats over episodes (every key of any episode)."""
    keys = []
    for s in stats_list:
        keys += [k for k in s if k not in keys]
    out = {}
    for key in keys:
        fts = [s[key] for s in stats_list if key in s]
        means = np.stack([f["mean"] for f in fts])
        variances = np.stack([f["std"] ** 2 for f in fts])
        counts = np.stack([f["count"] for f in fts])
        total = counts.sum(axis=0)
        while counts.ndim < means.ndim:
            counts = np.expand_dims(counts, axis=-1)
        mean = (means * counts).sum(axis=0) / total
        var = ((variances + (means - mean) ** 2) * counts).sum(axis=0) / total
        agg = {"min": np.min(np.stack([f["min"] for f in fts]), axis=0),
               "max": np.max(np.stack([f["max"] for f in fts]), axis=0),
               "mean": mean, "std": np.sqrt(var), "count": total}
        for q in QUANTILE_KEYS:
            if all(q in f for f in fts):
                vals = np.stack([f[q] for f in fts])
                agg[q] = np.min(vals, axis=0) if int(q[1:]) <= 50 else np.max(vals, axis=0)
        out[key] = agg
    return out


def to_json(stats: dict[str, dict[str, np.ndarray]]) -> dict:
    """serialize_dict: arrays to (nested) lists of Python numbers."""
    return {k: {s: np.asarray(v).tolist() for s, v in ft.items()} for k, ft in stats.items()}
