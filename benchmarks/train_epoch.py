"""Seconds per T-s5 training epoch: the current loop against the previous one, same data, same run.

Previous loop (kept here as the baseline): per step the batch plan is built on the host and
copied to the device, the loss is read back with .item() (a host sync every step), and
validation runs through the numpy predict path. Current loop (CnnGruForceModel.fit): the
epoch's plan is copied once, losses stay on the device, validation runs on the device, one sync
per epoch. Both train the same recipe (batch 256, Adam 3e-4, shared-frame batches).
CPU rows always (one thread, and all cores for the current loop); GPU rows when CUDA is present.
Data: 24 trials x 400 downsampled frames of random maps (20 train, 4 validation).
"""

from __future__ import annotations

import os
import time

import numpy as np
import torch

from layerskin_exp.estimation import CnnGruForceModel
from layerskin_exp.estimation.cnn import (
    LAYER_MODES,
    CnnGru,
    batch_forward,
    segment_batches,
    shared_plan,
    weighted_smooth_l1,
)
from layerskin_exp.estimation.config import CnnConfig
from layerskin_exp.estimation.splits import trial_starts


class PreviousLoop(CnnGruForceModel):
    """The training loop as it was before the estimation package (per-step host sync)."""

    def _fit(self, dev, X, y, trials, X_val, y_val, trials_val):
        cfg = self.config
        rng = np.random.default_rng(cfg.seed)
        ch = np.concatenate([X, X[:, :1] - X[:, 1:2]], axis=1)
        self.norm_ = {"x_mean": ch.mean(axis=(0, 2, 3)).astype(np.float32),
                      "x_std": (ch.std(axis=(0, 2, 3)) + 1e-6).astype(np.float32),
                      "y_mean": y.mean(axis=0).astype(np.float32), "y_std": (y.std(axis=0) + 1e-6).astype(np.float32)}
        self.model_ = CnnGru(LAYER_MODES[self.layers], cfg.dropout).to(dev)
        opt = torch.optim.Adam(self.model_.parameters(), lr=cfg.lr)
        w = torch.tensor(cfg.axis_weights, dtype=torch.float32, device=dev)
        x_t = torch.as_tensor(self._inputs(X), device=dev)
        y_t = torch.as_tensor((y - self.norm_["y_mean"]) / self.norm_["y_std"], device=dev)
        starts = trial_starts(trials)
        yv_n = (np.asarray(y_val, np.float32) - self.norm_["y_mean"]) / self.norm_["y_std"]
        self.history_ = []
        for epoch in range(cfg.max_epochs):
            self.model_.train()
            batches = segment_batches(np.arange(len(X)), starts, cfg.segment_windows, cfg.batch_size, rng,
                                      cfg.max_train_windows)
            train_loss = 0.0
            for ends in batches:
                fidx, pos = shared_plan(ends, starts, self.seq_len)
                loss = weighted_smooth_l1(batch_forward(self.model_, x_t, fidx, pos),
                                          y_t[torch.as_tensor(ends, device=dev)], w, cfg.smooth_l1_beta)
                opt.zero_grad(set_to_none=True)
                loss.backward()
                opt.step()
                train_loss += loss.item() * len(ends)
            pred_v = self._predict_normalised(X_val, trials_val)
            val_loss = float(weighted_smooth_l1(torch.as_tensor(pred_v), torch.as_tensor(yv_n), w.cpu(),
                                                cfg.smooth_l1_beta))
            self.history_.append({"epoch": epoch, "train_loss": train_loss, "val_loss": val_loss})
        self.model_.eval()
        return self


def _data(n_trials=24, n=400):
    rng = np.random.default_rng(0)
    X = rng.random((n_trials * n, 2, 16, 16), dtype=np.float32)
    y = rng.normal(size=(n_trials * n, 3)).astype(np.float32)
    trials = np.repeat(np.arange(n_trials), n)
    tr = trials < n_trials - 4
    return X[tr], y[tr], trials[tr], X[~tr], y[~tr], trials[~tr]


def _epoch_s(cls, device: str, data, epochs: int) -> float:
    cfg = CnnConfig(max_epochs=epochs, patience=epochs, device=device)
    t0 = time.perf_counter()
    cls("T-s5", cfg).fit(*data)
    if device == "cuda":
        torch.cuda.synchronize()
    return (time.perf_counter() - t0) / epochs


def run(epochs: int = 2) -> dict:
    data = _data()
    threads = torch.get_num_threads()
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    res: dict = {"train_frames": len(data[0]), "epochs_timed": epochs, "cores": cores}
    try:
        torch.set_num_threads(1)
        _epoch_s(CnnGruForceModel, "cpu", data, 1)  # warm-up
        res["cpu_1thread_previous_s"] = round(_epoch_s(PreviousLoop, "cpu", data, epochs), 2)
        res["cpu_1thread_current_s"] = round(_epoch_s(CnnGruForceModel, "cpu", data, epochs), 2)
        torch.set_num_threads(cores)
        res[f"cpu_{cores}threads_current_s"] = round(_epoch_s(CnnGruForceModel, "cpu", data, epochs), 2)
        res["cpu_ratio_previous_over_current"] = round(res["cpu_1thread_previous_s"] / res["cpu_1thread_current_s"], 2)
        if torch.cuda.is_available():
            torch.set_num_threads(1)
            _epoch_s(CnnGruForceModel, "cuda", data, 1)
            res["gpu_previous_s"] = round(_epoch_s(PreviousLoop, "cuda", data, epochs), 3)
            res["gpu_current_s"] = round(_epoch_s(CnnGruForceModel, "cuda", data, epochs), 3)
            res["gpu_ratio_previous_over_current"] = round(res["gpu_previous_s"] / res["gpu_current_s"], 2)
    finally:
        torch.set_num_threads(threads)
    return res


if __name__ == "__main__":
    print(run())
