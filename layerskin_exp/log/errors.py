"""The session log's errors: every way a file can be unusable ends in a SessionFileError."""

from __future__ import annotations


class SessionFileError(Exception):
    """The file is not a readable layerskin session (missing, not MCAP, empty, foreign content,
    or damaged beyond reading); the message names the file and the problem."""


class SessionInUseError(SessionFileError):
    """Another live SessionWriter holds this file; the message names it (pid, host, start)."""
