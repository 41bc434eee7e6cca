"""Atomic file writes: a failed or interrupted write never leaves a half-written file."""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

__all__ = ["atomic_write", "atomic_write_json", "atomic_write_text"]


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def atomic_write(path: str | os.PathLike[str], write_fn: Callable[[Path], Any]) -> Path:
    """Write a file atomically: ``write_fn`` fills a temporary file, which then replaces ``path``.

    The temporary file lies in ``path``'s directory (so :func:`os.replace` is atomic) and keeps
    ``path``'s suffix (so tools that pick a format from the name, such as matplotlib or Pillow,
    see the right one). If ``write_fn`` raises, the temporary file is removed and ``path`` is
    untouched. The new file gets the usual permissions (0666 less the umask).

    Args:
        path: the destination.
        write_fn: called with the temporary file's path; must write the complete contents there.

    Returns:
        ``path`` as a ``Path``.
    """
    dest = Path(path)
    directory = dest.parent if str(dest.parent) else Path(".")
    fd, tmp_name = tempfile.mkstemp(dir=directory, prefix=f".{dest.name}.", suffix=dest.suffix)
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        write_fn(tmp)
        with open(tmp, "rb+") as f:  # the data is on disk before the rename makes it visible
            os.fsync(f.fileno())
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, dest)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise
    return dest


def atomic_write_text(path: str | os.PathLike[str], text: str, encoding: str = "utf-8") -> Path:
    """Write ``text`` to ``path`` atomically (see :func:`atomic_write`)."""
    return atomic_write(path, lambda tmp: tmp.write_text(text, encoding=encoding))


def atomic_write_json(path: str | os.PathLike[str], obj: Any, indent: int | None = 2) -> Path:
    """Write ``obj`` as JSON (plus a final newline) to ``path`` atomically.

    The object is serialised before anything is written, so an unserialisable object leaves
    no file behind. NaN and infinities are refused (they are not JSON): use None instead.
    """
    text = json.dumps(obj, indent=indent, allow_nan=False) + "\n"
    return atomic_write_text(path, text)
