"""The study's temporal multi-head CNN–GRU force model (PyTorch), sklearn-style.

Architecture (SPEC §6): a shared frame encoder — conv 3×3 C→32 stride 1, 32→64 stride 2,
64→64 stride 1 (padding 1, ReLU), flatten 4096, linear → 64 with ReLU, dropout 0.1 — applied to
every frame of a T-frame window, then three independent GRUs (hidden 64, one layer), one per force
axis, whose last step goes through a linear layer to one force each.

Training encodes each frame once per batch: a batch is made of a few contiguous segments of
windows, the union of their frames is encoded, and every window gathers its T encodings from
it (a frame shared by T windows is encoded once, not T times). The loss is the same as encoding
each window on its own (tests check loss and gradients agree).
"""

from __future__ import annotations

import copy
import os
from dataclasses import asdict

import numpy as np
import torch
from torch import nn
from tqdm.auto import tqdm

from analysis.config import CnnConfig
from analysis.metrics import split_trials

LAYER_MODES = {"T": 3, "S": 1, "D": 1}


def parse_configuration(name: str) -> tuple[str, int]:
    """'T-s5' -> ('T', 5)."""
    try:
        layers, seq = name.split("-s")
        seq_len = int(seq)
    except ValueError:
        raise ValueError(f"configuration {name!r}: expected '<T|S|D>-s<length>', e.g. 'T-s5'") from None
    if layers not in LAYER_MODES or seq_len < 1:
        raise ValueError(f"configuration {name!r}: layers must be T, S or D and the length >= 1")
    return layers, seq_len


def input_channels(maps: np.ndarray, layers: str) -> np.ndarray:
    """Model input channels from preprocessed maps (N, 2, 16, 16) [superficial, deep].

    T: (N, 3, 16, 16) superficial, deep, signed difference; S / D: (N, 1, 16, 16).
    """
    if layers == "T":
        return np.concatenate([maps, maps[:, :1] - maps[:, 1:2]], axis=1).astype(np.float32)
    if layers == "S":
        return np.ascontiguousarray(maps[:, :1], np.float32)
    if layers == "D":
        return np.ascontiguousarray(maps[:, 1:2], np.float32)
    raise ValueError(f"layers={layers!r}: must be T, S or D")


class CnnGru(nn.Module):
    """Frame encoder + three GRU heads. forward(x (B, T, C, 16, 16)) -> (B, 3)."""

    def __init__(self, in_channels: int, dropout: float = 0.1, hidden: int = 64, n_taxels: int = 16) -> None:
        super().__init__()
        flat = 64 * ((n_taxels + 1) // 2) ** 2  # 4096 for 16×16
        self.encoder = nn.Sequential(
            nn.Conv2d(in_channels, 32, 3, stride=1, padding=1), nn.ReLU(),
            nn.Conv2d(32, 64, 3, stride=2, padding=1), nn.ReLU(),
            nn.Conv2d(64, 64, 3, stride=1, padding=1), nn.ReLU(),
            nn.Flatten(), nn.Linear(flat, 64), nn.ReLU(), nn.Dropout(dropout))
        self.grus = nn.ModuleList([nn.GRU(64, hidden, num_layers=1, batch_first=True) for _ in range(3)])
        self.outs = nn.ModuleList([nn.Linear(hidden, 1) for _ in range(3)])

    def encode(self, frames: torch.Tensor) -> torch.Tensor:
        """(F, C, 16, 16) -> (F, 64)."""
        return self.encoder(frames)

    def heads(self, seq: torch.Tensor) -> torch.Tensor:
        """(B, T, 64) encodings -> (B, 3) forces (normalised units)."""
        return torch.cat([out(gru(seq)[0][:, -1]) for gru, out in zip(self.grus, self.outs, strict=True)], dim=1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        b, t = x.shape[:2]
        return self.heads(self.encode(x.reshape(b * t, *x.shape[2:])).reshape(b, t, -1))


def trial_starts(trials: np.ndarray) -> np.ndarray:
    """For every frame, the index of the first frame of its trial. trials (N,) contiguous ids."""
    trials = np.asarray(trials)
    new = np.r_[True, trials[1:] != trials[:-1]]
    return np.maximum.accumulate(np.where(new, np.arange(len(trials)), 0))


def window_indices(ends: np.ndarray, starts: np.ndarray, seq_len: int) -> np.ndarray:
    """(B, T) frame indices of the windows ending at `ends`; frames before a trial's start repeat it."""
    idx = ends[:, None] - (seq_len - 1) + np.arange(seq_len)[None, :]
    return np.maximum(idx, starts[ends][:, None])


def naive_plan(ends: np.ndarray, starts: np.ndarray, seq_len: int) -> tuple[np.ndarray, np.ndarray]:
    """Every window's frames gathered separately: (frame_idx (B*T,), positions (B, T))."""
    win = window_indices(ends, starts, seq_len)
    return win.reshape(-1), np.arange(win.size).reshape(win.shape)


def shared_plan(ends: np.ndarray, starts: np.ndarray, seq_len: int) -> tuple[np.ndarray, np.ndarray]:
    """Each distinct frame of the batch encoded once: (frame_idx (F,), positions (B, T) into it)."""
    win = window_indices(ends, starts, seq_len)
    frame_idx, inverse = np.unique(win, return_inverse=True)
    return frame_idx, inverse.reshape(win.shape)


def batch_forward(model: CnnGru, x: torch.Tensor, frame_idx: np.ndarray, positions: np.ndarray) -> torch.Tensor:
    """Encode x[frame_idx] once and gather the windows: -> (B, 3)."""
    dev = x.device
    enc = model.encode(x[torch.as_tensor(frame_idx, device=dev)])
    return model.heads(enc[torch.as_tensor(positions, device=dev)])


def weighted_smooth_l1(pred: torch.Tensor, target: torch.Tensor, weights: torch.Tensor, beta: float) -> torch.Tensor:
    """Smooth-L1 on normalised errors, mean over samples, weighted average over the three axes."""
    per_axis = nn.functional.smooth_l1_loss(pred, target, reduction="none", beta=beta).mean(dim=0)
    return (per_axis * weights).sum() / weights.sum()


def segment_batches(ends: np.ndarray, starts: np.ndarray, segment: int, batch_size: int,
                    rng: np.random.Generator, max_windows: int | None = None) -> list[np.ndarray]:
    """Shuffled batches of window ends made of contiguous segments of `segment` windows.

    ends: window end indices available for training (sorted). A segment never crosses a trial.
    """
    ends = np.sort(ends)
    cut = np.r_[True, (np.diff(ends) != 1) | (starts[ends[1:]] != starts[ends[:-1]])]
    run_id = np.cumsum(cut) - 1
    pos_in_run = np.arange(len(ends)) - np.flatnonzero(cut)[run_id]
    seg_key = run_id * (len(ends) + 1) + pos_in_run // segment
    _, seg_start = np.unique(seg_key, return_index=True)
    segments = np.split(ends, seg_start[1:])
    order = rng.permutation(len(segments))
    if max_windows is not None:
        keep, total = [], 0
        for i in order:
            if total >= max_windows:
                break
            keep.append(i)
            total += len(segments[i])
        order = np.asarray(keep, dtype=np.int64)
    per_batch = max(1, batch_size // segment)
    return [np.concatenate([segments[i] for i in order[a:a + per_batch]])
            for a in range(0, len(order), per_batch)]


def resolve_device(name: str) -> torch.device:
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name == "cuda" and not torch.cuda.is_available():
        raise RuntimeError("analysis.cnn.device=cuda but no CUDA device is visible; use auto or cpu")
    return torch.device(name)


class CnnGruForceModel:
    """Three-axis force from windows of skin maps.

    X: (N, 2, 16, 16) preprocessed maps [superficial, deep] of consecutive frames;
    y: (N, 3) force in N; trials: (N,) trial id of each frame (frames of a trial contiguous).
    The prediction for frame n uses the window of `seq_len` frames ending at n (the trial's first
    frame repeated before its start), so every frame gets one.
    """

    def __init__(self, configuration: str = "T-s5", config: CnnConfig | None = None, progress: bool = False) -> None:
        self.configuration = configuration
        self.layers, self.seq_len = parse_configuration(configuration)
        self.config = config or CnnConfig()
        self.progress = progress
        self.model: CnnGru | None = None
        self.norm: dict[str, np.ndarray] = {}
        self.history: list[dict] = []

    # -- data --------------------------------------------------------------------------------
    def _inputs(self, X: np.ndarray) -> np.ndarray:
        x = input_channels(np.asarray(X), self.layers)
        return (x - self.norm["x_mean"][None, :, None, None]) / self.norm["x_std"][None, :, None, None]

    def _device(self) -> torch.device:
        return resolve_device(self.config.device)

    # -- training ----------------------------------------------------------------------------
    def fit(self, X, y, trials=None, X_val=None, y_val=None, trials_val=None) -> CnnGruForceModel:
        """Train with early stopping on validation loss; without X_val, 15 % of the trials are held out."""
        cfg = self.config
        torch.set_num_threads(cfg.torch_threads or os.cpu_count() or 1)
        torch.manual_seed(cfg.seed)
        rng = np.random.default_rng(cfg.seed)
        X, y = np.asarray(X), np.asarray(y, np.float32)
        trials = np.zeros(len(X), np.int64) if trials is None else np.asarray(trials)
        if len(X) != len(y) or len(X) != len(trials):
            raise ValueError(f"X ({len(X)}), y ({len(y)}) and trials ({len(trials)}) must have one row per frame")
        if X_val is None:
            tr, va, _ = split_trials(trials, (0.85, 0.15, 1e-9), seed=cfg.seed)
            if len(va) == 0:
                va = tr[-1:]
            m_tr, m_va = np.isin(trials, tr), np.isin(trials, va)
            X, y, trials, X_val, y_val, trials_val = X[m_tr], y[m_tr], trials[m_tr], X[m_va], y[m_va], trials[m_va]
        ch = input_channels(X, self.layers)
        self.norm = {"x_mean": ch.mean(axis=(0, 2, 3)).astype(np.float32),
                     "x_std": (ch.std(axis=(0, 2, 3)) + 1e-6).astype(np.float32),
                     "y_mean": y.mean(axis=0).astype(np.float32), "y_std": (y.std(axis=0) + 1e-6).astype(np.float32)}
        del ch
        dev = self._device()
        self.model = CnnGru(LAYER_MODES[self.layers], cfg.dropout).to(dev)
        opt = torch.optim.Adam(self.model.parameters(), lr=cfg.lr)
        w = torch.tensor(cfg.axis_weights, dtype=torch.float32, device=dev)
        x_t = torch.as_tensor(self._inputs(X), device=dev)
        y_t = torch.as_tensor((y - self.norm["y_mean"]) / self.norm["y_std"], device=dev)
        starts = trial_starts(trials)
        yv_n = (np.asarray(y_val, np.float32) - self.norm["y_mean"]) / self.norm["y_std"]
        best, best_state, stale = np.inf, None, 0
        bar = tqdm(range(cfg.max_epochs), desc=f"{self.configuration} epochs", leave=False, disable=not self.progress)
        for epoch in bar:
            self.model.train()
            batches = segment_batches(np.arange(len(X)), starts, cfg.segment_windows, cfg.batch_size, rng,
                                      cfg.max_train_windows)
            train_loss = 0.0
            for ends in batches:
                fidx, pos = shared_plan(ends, starts, self.seq_len)
                loss = weighted_smooth_l1(batch_forward(self.model, x_t, fidx, pos),
                                          y_t[torch.as_tensor(ends, device=dev)], w, cfg.smooth_l1_beta)
                opt.zero_grad(set_to_none=True)
                loss.backward()
                opt.step()
                train_loss += loss.item() * len(ends)
            train_loss /= max(1, sum(len(b) for b in batches))
            pred_v = self._predict_normalised(X_val, trials_val)
            val_loss = float(weighted_smooth_l1(torch.as_tensor(pred_v), torch.as_tensor(yv_n),
                                                w.cpu(), cfg.smooth_l1_beta))
            self.history.append({"epoch": epoch, "train_loss": train_loss, "val_loss": val_loss})
            bar.set_postfix(train=f"{train_loss:.4f}", val=f"{val_loss:.4f}")
            if val_loss < best - 1e-6:
                best, stale = val_loss, 0
                best_state = copy.deepcopy(self.model.state_dict())
            else:
                stale += 1
                if stale >= cfg.patience:
                    break
        if best_state is not None:
            self.model.load_state_dict(best_state)
        self.model.eval()
        return self

    # -- inference ---------------------------------------------------------------------------
    @torch.no_grad()
    def _predict_normalised(self, X, trials=None, chunk: int = 4096) -> np.ndarray:
        if self.model is None:
            raise RuntimeError("CnnGruForceModel.predict before fit or load: call fit(X, y) first")
        self.model.eval()
        dev = next(self.model.parameters()).device
        trials = np.zeros(len(X), np.int64) if trials is None else np.asarray(trials)
        x = self._inputs(np.asarray(X))
        enc = torch.cat([self.model.encode(torch.as_tensor(x[a:a + chunk], device=dev))
                         for a in range(0, len(x), chunk)]) if len(x) else torch.zeros(0, 64, device=dev)
        win = window_indices(np.arange(len(x)), trial_starts(trials), self.seq_len)
        out = [self.model.heads(enc[torch.as_tensor(win[a:a + chunk], device=dev)]).cpu()
               for a in range(0, len(win), chunk)]
        return torch.cat(out).numpy() if out else np.zeros((0, 3), np.float32)

    def predict(self, X, trials=None) -> np.ndarray:
        """(N, 2, 16, 16) maps (+ trial ids) -> (N, 3) force in N."""
        return self._predict_normalised(X, trials) * self.norm["y_std"] + self.norm["y_mean"]

    # -- checkpoints -------------------------------------------------------------------------
    def save(self, path) -> None:
        """state_dict + configuration + normalisation statistics, loadable with weights_only=True."""
        if self.model is None:
            raise RuntimeError("nothing to save: fit the model first")
        torch.save({"state_dict": {k: v.cpu() for k, v in self.model.state_dict().items()},
                    "configuration": self.configuration, "config": asdict(self.config),
                    "norm": {k: torch.as_tensor(v) for k, v in self.norm.items()}}, path)

    @classmethod
    def load(cls, path, device: str = "auto") -> CnnGruForceModel:
        ck = torch.load(path, map_location="cpu", weights_only=True)
        cfg = CnnConfig(**{**ck["config"], "device": device})
        obj = cls(ck["configuration"], cfg)
        obj.norm = {k: v.numpy() for k, v in ck["norm"].items()}
        obj.model = CnnGru(LAYER_MODES[obj.layers], cfg.dropout)
        obj.model.load_state_dict(ck["state_dict"])
        obj.model.to(obj._device()).eval()
        return obj
