"""Atomic file output: write to a temporary file beside the target, then rename,
so an interrupted run never leaves a partial file that looks complete."""
from __future__ import annotations

import math
import os
import tempfile
from pathlib import Path


def umask() -> int:
    """The process umask (read without changing it for good)."""
    m = os.umask(0)
    os.umask(m)
    return m


def chmod_like_new(path, directory: bool = False) -> None:
    """Give a file made by mkstemp/mkdtemp (0600/0700) the mode a plain
    open()/mkdir() would have given it under the user's umask."""
    os.chmod(path, (0o777 if directory else 0o666) & ~umask())


def json_safe(obj):
    """``obj`` with every non-finite float replaced by None (JSON has no
    Infinity/NaN); containers are copied, numpy scalars and arrays converted."""
    try:
        import numpy as np
    except ImportError:  # pragma: no cover
        np = None
    if isinstance(obj, dict):
        return {k: json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    if np is not None and isinstance(obj, np.ndarray):
        return json_safe(obj.tolist())
    if np is not None and isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def atomic_write_with(path, write) -> Path:
    """Write ``path`` through ``write(tmp_path)``: a temporary file beside it
    (``.NAME.XXXX.part.SUFFIX``, mode as a plain open() under the umask gives)
    renamed into place once ``write`` returns; on any exception, Ctrl-C
    included, the temporary file is removed and ``path`` left as it was."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part" + path.suffix, dir=path.parent)
    os.close(fd)
    try:
        write(tmp)
        chmod_like_new(tmp)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise
    return path


def atomic_write_text(path, text: str) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part", dir=path.parent)
    try:
        with os.fdopen(fd, "w") as f:
            f.write(text)
        chmod_like_new(tmp)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise
    return path
