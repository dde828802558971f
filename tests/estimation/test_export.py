"""ONNX export: onnxruntime gives the PyTorch model's force, and the sidecar carries the preprocessing."""

import json
import subprocess
import sys

import numpy as np
import onnxruntime as ort

from layerskin_exp.estimation.splits import window_indices


def test_onnxruntime_matches_pytorch_through_the_cli(fitted_estimator, tmp_path):
    est, raw = fitted_estimator
    art = est.save(tmp_path / "T-s5.pt")
    r = subprocess.run([sys.executable, "-m", "layerskin_exp.estimation.export", str(art), "--format", "onnx"],
                       capture_output=True, text=True, timeout=240)
    assert r.returncode == 0, r.stderr[-2000:]
    side = json.loads((tmp_path / "T-s5.onnx.json").read_text())
    assert side["preprocess"]["layer_scale"] == [float(v) for v in est.preprocessor.layer_scale_]
    assert side["seq_len"] == 5 and side["slip"]["cue"] == "interlayer"
    enc = ort.InferenceSession(str(tmp_path / side["encoder"]["file"]), providers=["CPUExecutionProvider"])
    heads = ort.InferenceSession(str(tmp_path / side["heads"]["file"]), providers=["CPUExecutionProvider"])
    maps = est.preprocessor.transform(raw[5][0])
    e = enc.run(None, {"maps": maps})[0]
    win = window_indices(np.arange(len(maps)), np.zeros(len(maps), np.int64), side["seq_len"])
    force = heads.run(None, {"window": e[win]})[0]
    ref = est.force_model.predict(maps)
    assert np.abs(ref).max() > 0.5  # a real signal, not zeros
    np.testing.assert_allclose(force, ref, rtol=0, atol=1e-4)


def test_cli_refuses_what_is_not_an_artifact(tmp_path):
    bad = tmp_path / "x.pt"
    bad.write_bytes(b"nope")
    r = subprocess.run([sys.executable, "-m", "layerskin_exp.estimation.export", str(tmp_path / "none.pt")],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "no such estimator artifact" in r.stderr
