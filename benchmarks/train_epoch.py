"""CPU training speed of the CNN-GRU: the current loop against the loop of 2026-11-25, same data, same run.

Baseline (kept here, `TodayLoop`): CnnGruForceModel's loop before the demo work: the epoch's
batch plan copied once, losses on the device, one sync per epoch, maps in the default
(channels-first) layout. Current loop (CnnGruForceModel.fit): the same, with the maps and the
model channels-last, the layout oneDNN's CPU convolutions run fastest on.

Figures: training windows per second, one thread, for both loops at the study's batch (256), and
for the current loop at the demo's batch (`conf/analysis/demo.yaml`). CPU time
(time.process_time) is the measure, so that a machine shared with other work still gives a
fair ratio; wall time is reported beside it. GPU rows when CUDA is present.
Data: 24 trials x 400 downsampled frames of random maps (20 train, 4 validation).

`analysis=paper` on a GPU (when CUDA is present, or with `--paper` on CPU): one epoch of each of
the study's six configurations at the preset's settings on data the size of the full 100-position
campaign (900 trials x 210 downsampled frames, 70 % trained on, 15 % validated on), giving seconds
per epoch and the worst case of the preset (200 epochs each, no early stop). Speed does not
depend on the maps' values, so random maps measure it fairly.
"""

from __future__ import annotations

import time

import numpy as np
import torch
from tqdm.auto import tqdm

from layerskin_exp.estimation import CnnGruForceModel
from layerskin_exp.estimation.cnn import (
    LAYER_MODES,
    CnnGru,
    _to,
    input_channels,
    plan_epoch,
    segment_batches,
    weighted_smooth_l1,
)
from layerskin_exp.estimation.config import CnnConfig
from layerskin_exp.estimation.splits import split_trials, trial_starts, window_indices


class TodayLoop(CnnGruForceModel):
    """CnnGruForceModel's training loop as it was on 2026-11-25 (channels-first, no lr schedule)."""

    def _fit(self, dev, X, y, trials, X_val, y_val, trials_val):
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
        opt = torch.optim.Adam(model.parameters(), lr=cfg.lr, fused=dev.type == "cuda")
        w = torch.tensor(cfg.axis_weights, dtype=torch.float32, device=dev)
        x_t = _to(self._inputs(X), dev)
        y_t = _to((y - self.norm_["y_mean"]) / self.norm_["y_std"], dev)
        xv_t = _to(self._inputs(X_val), dev)
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
            self.history_.append({"epoch": epoch, "train_loss": train_loss, "val_loss": val_loss})
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


def _data(n_trials=24, n=400):
    rng = np.random.default_rng(0)
    X = rng.random((n_trials * n, 2, 16, 16), dtype=np.float32)
    y = rng.normal(size=(n_trials * n, 3)).astype(np.float32)
    trials = np.repeat(np.arange(n_trials), n)
    tr = trials < n_trials - 4
    return X[tr], y[tr], trials[tr], X[~tr], y[~tr], trials[~tr]


def _windows_per_s(cls, data, epochs: int, device: str = "cpu", **cfg) -> tuple[float, float]:
    """(windows per CPU second, windows per wall second) over `epochs` epochs of fit."""
    c = CnnConfig(max_epochs=epochs, patience=epochs, device=device, **cfg)
    c0, w0 = time.process_time(), time.perf_counter()
    cls("T-s5", c).fit(*data)
    if device == "cuda":
        torch.cuda.synchronize()
    cpu, wall = time.process_time() - c0, time.perf_counter() - w0
    n = epochs * (c.max_train_windows or len(data[0]))
    return n / cpu, n / wall


def analysis_preset(name: str):
    """The report's `analysis=<name>` preset, composed and validated as the report composes it."""
    import analysis.config  # noqa: F401 - stores the report's schemas
    from layerskin_exp.config import compose

    return compose("report", [f"analysis={name}"]).analysis


def paper_preset(device: str, epochs: int = 1, n_trials: int = 900, frames: int = 210) -> dict:
    """Seconds per epoch of each configuration of `analysis=paper` at full-campaign size."""
    paper = analysis_preset("paper").cnn
    n_train, n_val = round(0.70 * n_trials), round(0.15 * n_trials)
    rng = np.random.default_rng(1)
    X = rng.random(((n_train + n_val) * frames, 2, 16, 16), dtype=np.float32)
    y = rng.normal(size=(len(X), 3)).astype(np.float32)
    trials = np.repeat(np.arange(n_train + n_val), frames)
    tr = trials < n_train
    data = X[tr], y[tr], trials[tr], X[~tr], y[~tr], trials[~tr]
    res = {"paper_device": device, "paper_train_windows_per_epoch": int(tr.sum()), "paper_val_frames": int((~tr).sum())}
    total = 0.0
    for conf in paper.configurations:
        c = CnnConfig(max_epochs=epochs, patience=epochs, device=device)
        CnnGruForceModel(conf, CnnConfig(max_epochs=1, patience=1, device=device, max_train_windows=4096)).fit(*data)
        w0 = time.perf_counter()
        CnnGruForceModel(conf, c).fit(*data)
        if device == "cuda":
            torch.cuda.synchronize()
        s_per_epoch = (time.perf_counter() - w0) / epochs
        res[f"paper_{conf}_s_per_epoch"] = round(s_per_epoch, 2)
        total += s_per_epoch
    res["paper_worst_case_min"] = round(total * paper.max_epochs / 60, 1)
    return res


def run(epochs: int = 1, paper_cpu: bool = False) -> dict:
    data = _data()
    demo = analysis_preset("demo").cnn
    threads = torch.get_num_threads()
    res: dict = {"train_windows_per_epoch": len(data[0]), "epochs_timed": epochs, "threads": 1,
                 "measure": "training windows per CPU second (wall beside it)"}
    try:
        torch.set_num_threads(1)
        _windows_per_s(CnnGruForceModel, data, 1)  # warm-up (oneDNN primitive caches)
        _windows_per_s(TodayLoop, data, 1)
        for name, cls, cfg in (("today_b256", TodayLoop, {}), ("current_b256", CnnGruForceModel, {}),
                               (f"current_demo_b{demo.batch_size}", CnnGruForceModel,
                                {"batch_size": demo.batch_size, "segment_windows": demo.segment_windows})):
            cpu, wall = _windows_per_s(cls, data, epochs, **cfg)
            res[f"cpu_{name}_windows_per_cpu_s"] = round(cpu)
            res[f"cpu_{name}_windows_per_wall_s"] = round(wall)
        res["cpu_ratio_current_over_today_b256"] = round(
            res["cpu_current_b256_windows_per_cpu_s"] / res["cpu_today_b256_windows_per_cpu_s"], 2)
        if torch.cuda.is_available():
            _windows_per_s(CnnGruForceModel, data, 1, "cuda")
            for name, cls in (("today", TodayLoop), ("current", CnnGruForceModel)):
                res[f"gpu_{name}_windows_per_wall_s"] = round(_windows_per_s(cls, data, epochs, "cuda")[1])
            res["gpu_ratio_current_over_today"] = round(
                res["gpu_current_windows_per_wall_s"] / res["gpu_today_windows_per_wall_s"], 2)
            res.update(paper_preset("cuda"))
        elif paper_cpu:
            torch.set_num_threads(threads)
            res.update(paper_preset("cpu"))
    finally:
        torch.set_num_threads(threads)
    return res


if __name__ == "__main__":
    import sys

    print(run(paper_cpu="--paper" in sys.argv[1:]))
