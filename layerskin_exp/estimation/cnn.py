"""The study's temporal multi-head CNN–GRU force model (PyTorch), scikit-learn manners.

Architecture (SPEC §6): a shared frame encoder — conv 3×3 C→32 stride 1, 32→64 stride 2,
64→64 stride 1 (padding 1, ReLU), flatten 4096, linear → 64 with ReLU, dropout 0.1 — applied to
every frame of a T-frame window, then three independent GRUs (hidden 64, one layer), one per force
axis, whose last step goes through a linear layer to one force each.

Training encodes each frame once per batch: a batch is made of a few contiguous segments of
windows, the union of their frames is encoded, and every window gathers its T encodings from
it (a frame shared by T windows is encoded once, not T times). The loss is the same as encoding
each window on its own (tests check loss and gradients agree).

Training keeps the accelerator busy: the data, the epoch's batch plan (one copy per epoch) and the
validation set live on the device, and the host reads one number pair (train and validation
loss) per epoch, never per step.
"""

from __future__ import annotations

import numpy as np
import torch
from sklearn.base import BaseEstimator
from sklearn.utils.validation import check_is_fitted
from torch import nn
from tqdm.auto import tqdm

from layerskin_exp import rig
from layerskin_exp.estimation.config import CnnConfig
from layerskin_exp.estimation.splits import split_trials, trial_starts, window_indices

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

    def __init__(self, in_channels: int, dropout: float = 0.1, hidden: int = 64, n_taxels: int = rig.N_TAXELS) -> None:
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


def plan_epoch(batches: list[np.ndarray], starts: np.ndarray, seq_len: int):
    """The shared plans of a whole epoch, concatenated for one host-to-device copy.

    Returns (frame_idx (ΣF,), positions (ΣB, T) into each batch's own frames, ends (ΣB,),
    frame_bounds, window_bounds): batch b is frame_idx[frame_bounds[b]:frame_bounds[b+1]] etc.
    """
    plans = [shared_plan(ends, starts, seq_len) for ends in batches]
    fb = np.cumsum([0] + [len(f) for f, _ in plans]).tolist()
    wb = np.cumsum([0] + [len(e) for e in batches]).tolist()
    if not plans:
        return np.zeros(0, np.int64), np.zeros((0, seq_len), np.int64), np.zeros(0, np.int64), fb, wb
    return (np.concatenate([f for f, _ in plans]).astype(np.int64),
            np.concatenate([p for _, p in plans]).astype(np.int64),
            np.concatenate(batches).astype(np.int64), fb, wb)


def resolve_device(name: str) -> torch.device:
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name == "cuda" and not torch.cuda.is_available():
        raise RuntimeError("analysis.cnn.device=cuda but no CUDA device is visible; use auto or cpu")
    return torch.device(name)


def default_torch_threads(device: str = "auto") -> int:
    """CPU threads for training: one. The model's ops are small (16x16 maps), so intra-op threads
    mostly synchronise: one thread trained a CPU epoch faster than all cores both on a 16-core
    H100 host and on a 2-core machine (benchmarks/train_epoch), and with a GPU the host only
    launches kernels."""
    del device  # the same answer for CPU and GPU today; kept so callers say which they train on
    return 1


def _channels_last(x: torch.Tensor) -> torch.Tensor:
    """(N, C, H, W) maps stored channels-last: the layout oneDNN's CPU convolutions run fastest on
    (about 1.1x training windows per CPU second, benchmarks/train_epoch); the values are the same."""
    return x.contiguous(memory_format=torch.channels_last)


# Frames per encoder call at inference (validation every epoch, predict): (CPU, CUDA). On a CPU,
# 256 frames keep the first convolution's output (256 x 32 x 16 x 16 floats, 8 MiB) near the
# cache, and encode a 64-position demo validation set in 0.6x the time of 4096-frame calls
# (1.6 s vs 2.6 s for 22,864 frames, one thread); a GPU wants large calls.
PREDICT_CHUNK = (256, 4096)


def _to(a: np.ndarray, dev: torch.device) -> torch.Tensor:
    t = torch.from_numpy(np.ascontiguousarray(a))
    if dev.type == "cuda":
        return t.pin_memory().to(dev, non_blocking=True)
    return t


class CnnGruForceModel(BaseEstimator):
    """Three-axis force from windows of skin maps.

    X: (N, 2, 16, 16) preprocessed maps [superficial, deep] of consecutive frames;
    y: (N, 3) force in N; trials: (N,) trial id of each frame (frames of a trial contiguous).
    The prediction for frame n uses the window of `seq_len` frames ending at n (the trial's first
    frame repeated before its start), so every frame gets one.
    Fitted state: model_ (CnnGru, eval mode), norm_ (input channel and force mean/std),
    history_ (per epoch train and validation loss).
    """

    def __init__(self, configuration: str = "T-s5", config: CnnConfig | None = None, progress: bool = False) -> None:
        parse_configuration(configuration)  # a bad name fails here, not at fit
        self.configuration = configuration
        self.config = config or CnnConfig()
        self.progress = progress

    @property
    def layers(self) -> str:
        return parse_configuration(self.configuration)[0]

    @property
    def seq_len(self) -> int:
        return parse_configuration(self.configuration)[1]

    @property
    def history(self) -> list[dict]:
        return getattr(self, "history_", [])

    # -- data --------------------------------------------------------------------------------
    def _inputs(self, X: np.ndarray) -> np.ndarray:
        x = input_channels(np.asarray(X), self.layers)
        return (x - self.norm_["x_mean"][None, :, None, None]) / self.norm_["x_std"][None, :, None, None]

    def _device(self) -> torch.device:
        return resolve_device(self.config.device)

    def _check_fitted(self) -> None:
        check_is_fitted(self, "model_", msg="This %(name)s is not fitted yet: call fit(X, y) or load an artifact.")

    # -- training ----------------------------------------------------------------------------
    def fit(self, X, y, trials=None, X_val=None, y_val=None, trials_val=None) -> CnnGruForceModel:
        """Train with early stopping on validation loss; without X_val, 15 % of the trials are held out.

        Seeded from config.seed through a forked RNG: the caller's global torch RNG is untouched.
        """
        dev = self._device()
        with torch.random.fork_rng(devices=[dev.index or 0] if dev.type == "cuda" else []):
            torch.manual_seed(self.config.seed)
            return self._fit(dev, X, y, trials, X_val, y_val, trials_val)

    def _fit(self, dev, X, y, trials, X_val, y_val, trials_val) -> CnnGruForceModel:
        cfg = self.config
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
        trials_val = np.zeros(len(X_val), np.int64) if trials_val is None else np.asarray(trials_val)
        ch = input_channels(X, self.layers)
        self.norm_ = {"x_mean": ch.mean(axis=(0, 2, 3)).astype(np.float32),
                      "x_std": (ch.std(axis=(0, 2, 3)) + 1e-6).astype(np.float32),
                      "y_mean": y.mean(axis=0).astype(np.float32), "y_std": (y.std(axis=0) + 1e-6).astype(np.float32)}
        del ch
        self.model_ = model = CnnGru(LAYER_MODES[self.layers], cfg.dropout).to(dev)
        model.to(memory_format=torch.channels_last)
        opt = torch.optim.Adam(model.parameters(), lr=cfg.lr, fused=dev.type == "cuda")
        sched = (torch.optim.lr_scheduler.ReduceLROnPlateau(opt, factor=cfg.lr_plateau_factor,
                                                            patience=cfg.lr_plateau_patience, threshold=1e-6,
                                                            threshold_mode="abs", eps=0.0)
                 if cfg.lr_schedule == "plateau" else None)
        w = torch.tensor(cfg.axis_weights, dtype=torch.float32, device=dev)
        x_t = _channels_last(_to(self._inputs(X), dev))
        y_t = _to((y - self.norm_["y_mean"]) / self.norm_["y_std"], dev)
        xv_t = _channels_last(_to(self._inputs(X_val), dev))
        yv_t = _to((np.asarray(y_val, np.float32) - self.norm_["y_mean"]) / self.norm_["y_std"], dev)
        win_v = _to(window_indices(np.arange(len(X_val)), trial_starts(trials_val), self.seq_len), dev)
        starts = trial_starts(trials)
        self.history_ = []
        best, best_state, stale = np.inf, None, 0
        bar = tqdm(range(cfg.max_epochs), desc=f"{self.configuration} epochs", leave=False, disable=not self.progress)
        for epoch in bar:
            model.train()
            batches = segment_batches(np.arange(len(X)), starts, cfg.segment_windows, cfg.batch_size, rng,
                                      cfg.max_train_windows)
            fidx, pos, ends, fb, wb = (_to(a, dev) if isinstance(a, np.ndarray) else a
                                       for a in plan_epoch(batches, starts, self.seq_len))
            loss_sum = torch.zeros((), device=dev)
            for b in range(len(batches)):
                enc = model.encode(x_t[fidx[fb[b]:fb[b + 1]]])
                loss = weighted_smooth_l1(model.heads(enc[pos[wb[b]:wb[b + 1]]]), y_t[ends[wb[b]:wb[b + 1]]], w,
                                          cfg.smooth_l1_beta)
                opt.zero_grad(set_to_none=True)
                loss.backward()
                opt.step()
                loss_sum += loss.detach() * (wb[b + 1] - wb[b])
            val = weighted_smooth_l1(self._predict_tensor(xv_t, win_v), yv_t, w, cfg.smooth_l1_beta)
            train_loss, val_loss = torch.stack([loss_sum / max(1, wb[-1]), val]).tolist()  # the epoch's one sync
            self.history_.append({"epoch": epoch, "train_loss": train_loss, "val_loss": val_loss,
                                  "lr": opt.param_groups[0]["lr"]})
            if sched is not None:
                sched.step(val_loss)
            bar.set_postfix(train=f"{train_loss:.4f}", val=f"{val_loss:.4f}")
            if val_loss < best - 1e-6:
                best, stale = val_loss, 0
                best_state = {k: v.detach().clone() for k, v in model.state_dict().items()}
            else:
                stale += 1
                if stale >= cfg.patience:
                    break
        if best_state is not None:
            model.load_state_dict(best_state)
        model.eval()
        return self

    # -- inference ---------------------------------------------------------------------------
    @torch.no_grad()
    def _predict_tensor(self, x: torch.Tensor, win: torch.Tensor, chunk: int | None = None) -> torch.Tensor:
        """Normalised inputs (N, C, 16, 16) and windows (M, T) on the device -> (M, 3) normalised force.

        chunk: frames encoded per call; None: PREDICT_CHUNK for the device."""
        chunk = chunk or PREDICT_CHUNK[x.device.type == "cuda"]
        was_training = self.model_.training
        self.model_.eval()
        if len(x) == 0:
            return torch.zeros(0, 3, device=x.device)
        enc = torch.cat([self.model_.encode(x[a:a + chunk]) for a in range(0, len(x), chunk)])
        out = torch.cat([self.model_.heads(enc[win[a:a + chunk]]) for a in range(0, len(win), chunk)])
        self.model_.train(was_training)
        return out

    def _predict_normalised(self, X, trials=None) -> np.ndarray:
        self._check_fitted()
        dev = next(self.model_.parameters()).device
        trials = np.zeros(len(X), np.int64) if trials is None else np.asarray(trials)
        if len(X) == 0:
            return np.zeros((0, 3), np.float32)
        x = _channels_last(_to(self._inputs(np.asarray(X)), dev))
        win = _to(window_indices(np.arange(len(X)), trial_starts(trials), self.seq_len), dev)
        return self._predict_tensor(x, win).cpu().numpy()

    def predict(self, X, trials=None) -> np.ndarray:
        """(N, 2, 16, 16) maps (+ trial ids) -> (N, 3) force in N."""
        return self._predict_normalised(X, trials) * self.norm_["y_std"] + self.norm_["y_mean"]

    # -- state -------------------------------------------------------------------------------
    def state(self) -> dict:
        """Everything fitted, as tensors and plain values (torch.load(weights_only=True) reads it)."""
        self._check_fitted()
        from dataclasses import asdict

        return {"state_dict": {k: v.detach().cpu() for k, v in self.model_.state_dict().items()},
                "configuration": self.configuration, "config": asdict(self.config),
                "norm": {k: torch.as_tensor(v) for k, v in self.norm_.items()},
                "history": [dict(h) for h in self.history]}

    @classmethod
    def from_state(cls, st: dict, device: str = "auto") -> CnnGruForceModel:
        cfg = CnnConfig(**{**st["config"], "device": device})
        obj = cls(st["configuration"], cfg)
        obj.norm_ = {k: v.numpy() for k, v in st["norm"].items()}
        obj.model_ = CnnGru(LAYER_MODES[obj.layers], cfg.dropout)
        obj.model_.load_state_dict(st["state_dict"])
        obj.model_.to(obj._device()).eval()
        obj.history_ = list(st.get("history", []))
        return obj
