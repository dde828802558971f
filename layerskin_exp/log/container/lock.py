"""One live writer per session file: an exclusive OS lock, and a note naming its owner.

Two processes writing the same trial to one file interleave their bytes: one's data replaces
the other's, or a tail lands after the footer. So a SessionWriter takes fcntl.flock(LOCK_EX) on
its file before touching its contents, and holds it until close. The lock belongs to the open
file, so the kernel drops it when the writer exits or is killed: a file left by a crashed run
is not held by anyone and may be replaced, a file being written never is.

Who holds a lock is written beside the file, in `<file>.owner` (pid, host, start time), so the
refusal can say which process to look at. The note is removed at close; one left by a crash is
harmless (the lock, not the note, decides) and is overwritten by the next owner, who also removes
the note's temporary copies (`<file>.<pid>.tmp`) a writer killed while writing it left behind.
"""

from __future__ import annotations

import fcntl
import glob
import json
import os
import socket
import time
from dataclasses import dataclass
from pathlib import Path

from layerskin_exp.log.errors import SessionInUseError

OWNER_SUFFIX = ".owner"


def owner_path(path: Path) -> Path:
    return path.with_name(path.name + OWNER_SUFFIX)


def describe_owner(path: Path) -> str:
    """'pid 123 on host lab-2, writing since 2025-01-01 12:00:00' (or why it is unknown)."""
    try:
        info = json.loads(owner_path(path).read_text())
        return f"pid {int(info['pid'])} on host {info['host']}, writing since {info['started']}"
    except (OSError, ValueError, KeyError, TypeError):
        return f"a process whose owner note {owner_path(path).name} is missing or unreadable"


def _in_use(path: Path) -> SessionInUseError:
    return SessionInUseError(
        f"{path}: another SessionWriter is writing this file ({describe_owner(path)}). Two writers "
        f"on one file would destroy each other's data; nothing was written. Wait for that run to "
        f"finish, or stop that process, or write this trial to another path"
    )


@dataclass
class WriterLock:
    """An open, exclusively locked, empty session file (fd) and its owner note. Whoever closes
    fd releases the lock (SessionWriter hands it to its file object)."""

    path: Path
    fd: int

    @classmethod
    def acquire(cls, path: Path, *, overwrite: bool) -> WriterLock:
        """Open `path` for writing, locked. Never truncates a file another writer holds."""
        path = Path(path)
        for _ in range(20):  # retried only when the name moved to another file while locking
            flags = os.O_RDWR | os.O_CREAT | getattr(os, "O_CLOEXEC", 0) | (0 if overwrite else os.O_EXCL)
            try:
                fd = os.open(path, flags, 0o644)
            except FileExistsError:
                if held(path):
                    raise _in_use(path) from None
                raise FileExistsError(
                    f"session file {path} already exists; refusing to overwrite recorded data "
                    f"(choose another path or pass overwrite=True)"
                ) from None
            except IsADirectoryError:
                raise IsADirectoryError(f"{path} is a directory, not a session file path") from None
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                os.close(fd)
                raise _in_use(path) from None
            except BaseException:
                os.close(fd)
                raise
            # Locked, but the name may meanwhile point at another file: the previous holder may
            # have renamed its finished file away (ours is then that finished file: leave it).
            try:
                same = os.path.samestat(os.fstat(fd), os.stat(path))
            except FileNotFoundError:
                same = False
            if not same:
                os.close(fd)
                continue
            os.ftruncate(fd, 0)
            lock = cls(path, fd)
            lock._write_owner()
            return lock
        raise SessionInUseError(f"{path}: the file kept being replaced while locking it; is another run "
                                f"writing the same trial?")

    def _write_owner(self) -> None:
        # Only a holder of the lock writes the note, so any other temporary copy of it is a dead
        # holder's (killed between writing it and moving it into place): remove it.
        for stale in self.path.parent.glob(f"{glob.escape(self.path.name)}.*.tmp"):
            if stale.name[len(self.path.name) + 1:-len(".tmp")].isdigit():
                try:
                    stale.unlink()
                except OSError:
                    pass
        info = {
            "pid": os.getpid(),
            "host": socket.gethostname(),
            "started": time.strftime("%Y-%m-%d %H:%M:%S %z"),
            "file": self.path.name,
        }
        tmp = self.path.with_name(f"{self.path.name}.{os.getpid()}.tmp")
        try:
            tmp.write_text(json.dumps(info))
            os.replace(tmp, owner_path(self.path))
        except OSError:
            pass  # the note only helps the error message; the lock is what protects the file

    def move(self, dst) -> Path:
        """Rename the locked file to dst (atomic, fsynced), still holding the lock."""
        dst = Path(dst)
        self._remove_owner()
        os.replace(self.path, dst)
        _fsync_dir(dst.parent)
        self.path = dst
        return dst

    def _remove_owner(self) -> None:
        try:
            owner_path(self.path).unlink()
        except OSError:
            pass

    def forget_owner(self) -> None:
        """Remove the owner note; the caller then closes the file, which drops the lock."""
        self._remove_owner()


def held(path: Path) -> bool:
    """Whether a live writer holds `path` (probed with a non-blocking shared lock): a file being
    written, as against one a crashed or killed run left (the kernel dropped its lock)."""
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_CLOEXEC", 0))
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        return False
    except BlockingIOError:
        return True
    finally:
        os.close(fd)


def _fsync_dir(folder: Path) -> None:
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)
