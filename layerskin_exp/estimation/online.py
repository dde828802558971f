"""Live estimation at the readout rate: each frame pair in, the latest force and slip out.

Mapping of the 5x downsampling onto the 424 Hz stream (see `DownsampleStream`): every raw frame
is pushed into the study's smoothing filter; every fifth one completes a downsampled frame (the
filter of block k reaches 4 raw frames past the block, 9.4 ms). Only then is anything encoded:
that frame is encoded once, its encoding and its three GRU input projections are cached, and the
T-s5 window is the last five cached frames (the first repeated at the start, as in training).
The GRU heads run over the window from a zero state (the model was trained on windows, not on a
running state). Between completions `update` returns the latest estimate unchanged (new=False).
The slip cue of the downsampled frame goes through the detector's causal stream.

`update` returns None until the first downsampled frame is complete and the baseline (the first
`baseline_frames` raw frames) is known.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np
import torch

from layerskin_exp.estimation.artifact import Estimator, cue_values
from layerskin_exp.estimation.cnn import input_channels
from layerskin_exp.estimation.preprocess import DownsampleStream


@dataclass(frozen=True, slots=True)
class Estimate:
    """force_n (3,) Fx, Fy, Fz in N; slip_score in MAD units (NaN without a detector); slip: this
    frame confirms a slip event (the score peaked at the previous frame, at or above the fitted
    threshold; the detector's latency offset is fitted on that peak's time); t_ns: time of the
    downsampled frame (the filter's centre, on the frames' clock); frame: its index k; new:
    computed at this update."""

    t_ns: int
    frame: int
    force_n: np.ndarray
    slip_score: float
    slip: bool
    new: bool


def _sigmoid(x: np.ndarray) -> np.ndarray:
    return 1.0 / (1.0 + np.exp(-x))


class GruHeads:
    """The three GRU heads and output layers of a CnnGru in numpy, for one window at a time.

    The three heads are laid out as one GRU of hidden size 3H whose weights are block-diagonal
    (head a reads only its own hidden units), gates grouped [r | z | n] over all heads: one
    matrix-vector product per step instead of three. The zero blocks add exact zeros, so each
    head computes what torch.nn.GRU computes (r, z, n gates;
    n = tanh(W_in x + b_in + r ⊙ (W_hn h + b_hn))).
    project(enc (64,)) -> (9H,) input projections W_ih·x + b_ih (cached per frame);
    run(projections, a sequence of T of them) -> (3,) normalised force.
    """

    def __init__(self, model) -> None:
        hd = model.grus[0].hidden_size
        n = len(model.grus)
        w_ih = np.zeros((3, n, hd, model.grus[0].input_size), np.float32)
        b_ih = np.zeros((3, n, hd), np.float32)
        w_hh = np.zeros((3, n, hd, n, hd), np.float32)
        b_hh = np.zeros((3, n, hd), np.float32)
        for a, g in enumerate(model.grus):
            wi, wh = g.weight_ih_l0.detach().cpu().numpy(), g.weight_hh_l0.detach().cpu().numpy()
            bi, bh = g.bias_ih_l0.detach().cpu().numpy(), g.bias_hh_l0.detach().cpu().numpy()
            for gate in range(3):  # torch's row order within a GRU: r, z, n
                rows = slice(gate * hd, (gate + 1) * hd)
                w_ih[gate, a], b_ih[gate, a] = wi[rows], bi[rows]
                w_hh[gate, a, :, a], b_hh[gate, a] = wh[rows], bh[rows]
        self.hidden = n * hd
        self.w_ih = w_ih.reshape(3 * n * hd, -1)
        self.b_ih = b_ih.reshape(-1)
        self.w_hh = np.ascontiguousarray(w_hh.reshape(3 * n * hd, n * hd))
        self.b_hh = b_hh.reshape(-1)
        w_out = np.zeros((n, n, hd), np.float32)
        for a, o in enumerate(model.outs):
            w_out[a, a] = o.weight.detach().cpu().numpy()[0]
        self.w_out = w_out.reshape(n, n * hd)
        self.b_out = np.array([float(o.bias.detach().cpu()[0]) for o in model.outs], np.float32)

    def project(self, enc: np.ndarray) -> np.ndarray:
        return self.w_ih @ enc + self.b_ih

    def run(self, gi_seq) -> np.ndarray:
        hd = self.hidden
        h = np.zeros(hd, np.float32)
        for t, gi in enumerate(gi_seq):
            gh = self.b_hh if t == 0 else self.w_hh @ h + self.b_hh
            rz = _sigmoid(gi[:2 * hd] + gh[:2 * hd])
            n = np.tanh(gi[2 * hd:] + rz[:hd] * gh[2 * hd:])
            z = rz[hd:]
            h = n + z * (h - n)  # (1 - z) n + z h
        return self.w_out @ h + self.b_out


class _TorchBackend:
    """Frame encoder in PyTorch; per frame the heads' input projections are cached (numpy heads)."""

    def __init__(self, model) -> None:
        self.layers = model.layers
        self.encoder = model.model_.encoder
        self.heads = GruHeads(model.model_)
        norm = model.norm_
        self.x_mean, self.x_inv_std = norm["x_mean"][:, None, None], (1.0 / norm["x_std"])[:, None, None]
        self.y_mean, self.y_std = norm["y_mean"], norm["y_std"]

    def encode(self, maps: np.ndarray) -> np.ndarray:
        x = (input_channels(maps[None], self.layers)[0] - self.x_mean) * self.x_inv_std
        with torch.inference_mode():
            enc = self.encoder(torch.from_numpy(np.ascontiguousarray(x, np.float32))[None])[0].numpy()
        return self.heads.project(enc)

    def force(self, window: list) -> np.ndarray:
        return self.heads.run(window) * self.y_std + self.y_mean


class _OnnxBackend:
    """The exported graphs in onnxruntime (one thread): cached encodings, heads on the window."""

    def __init__(self, estimator: Estimator, threads: int) -> None:
        import onnxruntime as ort

        from layerskin_exp.estimation.onnx_graphs import EncoderGraph, HeadsGraph, onnx_bytes

        so = ort.SessionOptions()
        so.intra_op_num_threads, so.inter_op_num_threads = threads, 1
        so.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
        enc, heads = onnx_bytes(EncoderGraph(estimator), HeadsGraph(estimator), estimator.force_model.seq_len)
        self.enc = ort.InferenceSession(enc, so, providers=["CPUExecutionProvider"])
        self.heads = ort.InferenceSession(heads, so, providers=["CPUExecutionProvider"])

    def encode(self, maps: np.ndarray) -> np.ndarray:
        return self.enc.run(None, {"maps": maps[None]})[0][0]

    def force(self, window: list) -> np.ndarray:
        return self.heads.run(None, {"window": np.stack(window)[None]})[0][0]


class OnlineEstimator:
    """update(superficial_counts (16, 16), deep_counts (16, 16), t_ns) -> Estimate | None.

    backend: "torch" (PyTorch encoder, numpy GRU heads over cached input projections) or "onnx"
    (the exported graphs in onnxruntime; normalisation inside the graph, force in N out of it).
    """

    def __init__(self, estimator: Estimator, threads: int | None = 1, backend: str = "onnx") -> None:
        self.est = estimator
        self.model = estimator.force_model
        self.model.model_.to("cpu").eval()
        if threads is not None and backend == "torch":  # one thread is fastest for one frame
            torch.set_num_threads(threads)
        self.seq_len = self.model.seq_len
        if backend == "torch":
            self.backend = _TorchBackend(self.model)
        elif backend == "onnx":
            self.backend = _OnnxBackend(estimator, threads or 1)
        else:
            raise ValueError(f"backend={backend!r}: must be 'torch' or 'onnx'")
        self.backend_name = backend
        self.stream = DownsampleStream(estimator.preprocessor)
        self.slip = estimator.slip_detector.stream() if estimator.slip_detector is not None else None
        self.reset()

    @classmethod
    def from_artifact(cls, path, threads: int | None = 1, backend: str = "onnx") -> OnlineEstimator:
        return cls(Estimator.load(path, device="cpu"), threads, backend)

    def reset(self) -> None:
        """A new trial (a new contact, a new baseline): forget every frame seen."""
        self.stream.reset()
        if self.slip is not None:
            self.slip.reset()
        self.cache: deque = deque(maxlen=self.seq_len)
        self.latest: Estimate | None = None

    def update(self, superficial_counts, deep_counts, t_ns: int) -> Estimate | None:
        frame = np.stack([np.asarray(superficial_counts), np.asarray(deep_counts)])
        done = self.stream.push(frame, t_ns)
        if not done:
            if self.latest is not None and self.latest.new:
                self.latest = Estimate(self.latest.t_ns, self.latest.frame, self.latest.force_n,
                                       self.latest.slip_score, self.latest.slip, False)
            return self.latest
        for k, maps, t_k in done:
            self.cache.append(self.backend.encode(maps))  # each frame encoded once
            window = [self.cache[0]] * (self.seq_len - len(self.cache)) + list(self.cache)
            force = self.backend.force(window)
            score, flag = np.nan, False
            if self.slip is not None:
                tot = maps.sum(axis=(-2, -1))
                cue = float(cue_values(self.est.slip_cue, tot[0], tot[1], force))
                score, flag = self.slip.update(cue)
            self.latest = Estimate(t_k, k, force.astype(np.float32), float(score), bool(flag), True)
        return self.latest
