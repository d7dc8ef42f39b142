"""JSON encoding of the numpy/path values that records and checkpoint metadata contain, and the safe way
to write any output: locations checked before the work starts, files replaced atomically.

Atomic means: the bytes go to a temporary file in the same folder, are flushed to disk, and the temporary
file is renamed over the target. A reader sees the old file or the new one, never a cut-off one (a full
disk leaves the previous record as it was); a symlink at the target is replaced, never followed.
"""
from __future__ import annotations

import contextlib
import errno
import os
import tempfile
from pathlib import Path

import numpy as np

from tcot_hybrid.errors import OutputError

PROBE_BYTES = 64 * 1024  # written (and removed) when an output folder is checked: a full disk shows up here


def json_default(o):
    """``json.dumps(default=...)`` hook: numpy scalars/arrays and paths as plain JSON values."""
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def _why(exc: OSError) -> str:
    if exc.errno == errno.ENOSPC:
        return "the disk is full"
    if exc.errno == errno.EROFS:
        return "the file system is read-only"
    if exc.errno in (errno.EACCES, errno.EPERM):
        return "permission denied"
    if exc.errno == errno.EDQUOT:
        return "the disk quota is exceeded"
    return exc.strerror or str(exc)


def check_output_dir(path: str | Path, *, what: str = "--out") -> Path:
    """Make sure ``path`` is (or can be made) a folder we can write files into, before any work runs:
    not an existing file, creatable, writable, with room for a probe of PROBE_BYTES. Raises OutputError."""
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise OutputError(f"{what} {str(p)!r} is an existing file, not a folder; give a folder path")
    try:
        p.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"{what} {str(p)!r} cannot be created: {_why(exc)}") from exc
    try:
        fd, tmp = tempfile.mkstemp(dir=p, prefix=".tcot-probe-")
    except OSError as exc:
        raise OutputError(f"{what} {str(p)!r} is not writable: {_why(exc)}") from exc
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(b"\0" * PROBE_BYTES)
            f.flush()
            os.fsync(f.fileno())
    except OSError as exc:
        raise OutputError(f"{what} {str(p)!r} cannot take a record: {_why(exc)}") from exc
    finally:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
    return p


def check_output_file(path: str | Path, *, what: str) -> Path:
    """Make sure file ``path`` can be written later: not a directory, its folder writable (see
    check_output_dir). Raises OutputError naming ``what`` (e.g. ``--video``)."""
    p = Path(path)
    if p.is_dir():
        raise OutputError(f"{what} {str(p)!r} is a directory; give a file path")
    check_output_dir(p.parent if str(p.parent) else Path("."), what=f"{what} folder")
    return p


def atomic_write_bytes(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (temporary file in the same folder, fsync, rename). On any
    failure the previous file is untouched and the temporary file removed; OSError becomes OutputError."""
    p = Path(path)
    if p.is_dir() and not p.is_symlink():
        raise OutputError(f"cannot write {str(p)!r}: it is a directory")
    try:
        fd, tmp = tempfile.mkstemp(dir=p.parent, prefix=f".{p.name}.", suffix=".tmp")
    except OSError as exc:
        raise OutputError(f"cannot write {str(p)!r}: {_why(exc)}") from exc
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp, 0o644)
        os.replace(tmp, p)  # replaces a symlink itself, never the file it points to
    except OSError as exc:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        kept = " (the previous file is left as it was)" if p.exists() else ""
        raise OutputError(f"cannot write {str(p)!r}: {_why(exc)}{kept}") from exc
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    return p


def atomic_write_text(path: str | Path, text: str) -> Path:
    return atomic_write_bytes(path, text.encode("utf-8"))
