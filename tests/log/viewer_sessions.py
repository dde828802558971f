"""Sessions for the viewer tests: deterministic, a second of skin at most, written in well under one."""

from __future__ import annotations

import math

from log_records import frame, records

from layerskin_exp.log import SessionWriter
from layerskin_exp.types import ProtocolEvent, TwoLayerFrame, Wrench

N_FRAMES = 200


def write_platform_session(path, *, blank_superficial: bool = False):
    """Skin frames (log_records.frame), a wrench at half the frame rate (a slow sine in Fz, so the
    plot has a shape), and two protocol events: the panels of the browser test and nothing else."""
    with SessionWriter(path, metadata={"protocol": "viewer_test"}, labels={"trial": 0},
                       epoch_offset_ns=1_700_000_000_000_000_000) as w:
        for i in range(N_FRAMES):
            f = frame(i)
            if blank_superficial:
                f = TwoLayerFrame(f.superficial * 0, f.deep, f.seq, f.device_t_ns, f.host_t_ns)
            w.write(f)
            if i % 2 == 0:
                fz = -2.0 + 1.5 * math.sin(i / 15)
                w.write(Wrench([0.1 * math.cos(i / 9), 0.05, fz], [0.0, 0.001, 0.0], i // 2, f.device_t_ns,
                               f.host_t_ns + 1000))
            if i in (0, N_FRAMES // 2):
                w.write(ProtocolEvent("phase", "press" if i else "approach", f.host_t_ns, f.device_t_ns,
                                      {"i": i}))
    return path


def write_full_session(path):
    """log_records.records: every stream the writer knows (wrench, stage, TCP, gripper, markers)."""
    with SessionWriter(path, metadata={"protocol": "viewer_test"}, labels={"trial": 1}) as w:
        for r in records(120):
            w.write(r)
    return path
