"""The session log: one MCAP file per trial, written crash-safely, read back as numpy arrays.

    from layerskin_exp.log import SessionWriter, load_session
    with SessionWriter(path, metadata={...}, labels={...}) as w:
        w.write(record)
    s = load_session(path)

Stream layout of Session.streams (every stream also has "t_ns": device time mapped onto the
host timeline, "host_t_ns", "device_t_ns", "seq"; all (N,) int64):
    skin     superficial, deep (N, 16, 16) uint16
    wrench   force_n (N, 3), torque_nm (N, 3), status (N,)
    stage    position_mm (N, 3)
    tcp      position_m (N, 3), orientation_xyzw (N, 4), frame_id list[str]
    gripper  position_mm, requested_mm (N,) float; speed, force, fault (N,) int; object_detected (N,) bool
    markers  marker_id (N,), position_m (N, 3), orientation_xyzw (N, 4), corners_px (N, 4, 2), frame_seq
    camera   image (N, H, W) uint8 (or a list if sizes differ)
    events   kind, message list[str], detail list[dict]  (t_ns = host_t_ns, no seq)
    transforms  parent_frame_id, child_frame_id list[str], translation_m (N, 3), rotation_xyzw (N, 4)
             (t_ns = host_t_ns; the frame tree of layerskin_exp.log.view.frame_tree)
Poses written with write_pose(p, topic) on other topics appear under their topic name.

One live writer per file: SessionWriter holds an OS lock on its file until close; a second
writer raises SessionInUseError naming the first (pid, host, start time).

A damaged file is read around the damage: Session.lost lists what could not be read (time span,
messages per stream, why), Session.damaged says any damage was found, and Session.complete is
true only for a finished, undamaged file whose outcome is "complete". Anything that cannot be
read at all raises SessionFileError naming the file.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

from layerskin_exp.log.errors import SessionFileError, SessionInUseError

# The reader and the writer (numpy, scipy's rotations, OpenCV's image codecs, the MCAP schemas) load
# on first use: a command's config check that only looks at a path (analysis.sessions.sessions_problem,
# through layerskin_exp.log.container.scan) does not pay for them (benchmarks/cli_help).
_WHERE = {"LostRange": "session.reader", "Session": "session.reader", "SessionWarning": "session.reader",
          "load_session": "session.reader", "SessionClosedError": "session.writer",
          "SessionWriter": "session.writer"}

if TYPE_CHECKING:
    from layerskin_exp.log.session.reader import LostRange, Session, SessionWarning, load_session
    from layerskin_exp.log.session.writer import SessionClosedError, SessionWriter


def __getattr__(name: str):
    if name not in _WHERE:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{_WHERE[name]}"), name)
    globals()[name] = value
    return value

__all__ = [
    "LostRange",
    "Session",
    "SessionClosedError",
    "SessionFileError",
    "SessionInUseError",
    "SessionWarning",
    "SessionWriter",
    "load_session",
]


def __dir__() -> list[str]:
    return sorted([*globals(), *__all__])
