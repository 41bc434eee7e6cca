"""Writing files: atomic writes (a file is either its earlier complete self or its new
complete self) and the checks that an output can be written, made before any work.

Every file jaxais writes goes through :func:`atomic_write`: the contents fill a temporary file in
the target's directory, which then replaces the target with :func:`os.replace`. A failed or
interrupted write leaves the earlier file (if any) as it was. The command-line layer
(:mod:`jaxais.cli`) removes the temporary files still in flight when a signal ends a script, after
running :data:`ON_SIGNAL`.
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any


class UserError(ValueError):
    """A mistake by the user (a bad path, flag or argument): one line, exit status 2, from a
    script (:mod:`jaxais.cli`); a ``ValueError`` for a library caller."""


class ArgumentTypeError(UserError, TypeError):
    """An argument of the wrong type: a TypeError, and a UserError like every other bad
    argument, so callers catching ValueError and the scripts see one line too."""


def check_type(value: Any, kind: Any, name: str, what: str, hint: str = "") -> None:
    """:class:`ArgumentTypeError` naming the argument ``name`` unless ``value`` is a ``kind``:
    "``name`` must be ``what``, got <its type> (<a short value>)``hint``"."""
    if not isinstance(value, kind):
        got = type(value).__name__
        if isinstance(value, str | int | float):
            got += f" {value!r:.40}"
        raise ArgumentTypeError(f"{name} must be {what}, got {got}{hint}")


IN_FLIGHT: set[Path] = set()
"""Temporary files being written right now (removed by the CLI's signal handler)."""
ON_SIGNAL: list[Callable[[], object]] = []
"""What must still happen when a signal ends a script at once, newest first (the seed ledger
stops its child processes here); each entry is removed by whoever added it."""


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def atomic_write(path: str | os.PathLike[str], write_fn: Callable[[Path], Any]) -> Path:
    """Write a file atomically: ``write_fn`` fills a temporary file, which then replaces ``path``.

    The temporary file lies in ``path``'s directory (so the replace is atomic) and keeps
    ``path``'s suffix (matplotlib picks a format from the name). If ``write_fn`` raises, the
    temporary file is removed and ``path`` is untouched. The new file gets the usual permissions
    (0666 less the umask).

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
    IN_FLIGHT.add(tmp)
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
    finally:
        IN_FLIGHT.discard(tmp)
    return dest


def atomic_write_text(path: str | os.PathLike[str], text: str, encoding: str = "utf-8") -> Path:
    """Write ``text`` to ``path`` atomically (see :func:`atomic_write`)."""
    return atomic_write(path, lambda tmp: tmp.write_text(text, encoding=encoding))


def atomic_write_json(path: str | os.PathLike[str], obj: Any, indent: int | None = 2) -> Path:
    """Write ``obj`` as JSON (plus a final newline) to ``path`` atomically.

    The object is serialised before anything is written, so an unserialisable object leaves no
    file behind. NaN and infinities are refused (they are not JSON): use None instead.
    """
    text = json.dumps(obj, indent=indent, allow_nan=False) + "\n"
    return atomic_write_text(path, text)


def check_writable_dir(path: str | os.PathLike[str]) -> Path:
    """Check that ``path`` is an existing directory this process can create files in.

    Args:
        path: the directory ("" means the current directory).

    Returns:
        The directory as a ``Path``.

    Raises:
        UserError: it does not exist, is not a directory, or is not writable.
    """
    d = Path(path) if str(path) else Path(".")
    if not d.exists():
        raise UserError(f"{d}: directory does not exist")
    if not d.is_dir():
        raise UserError(f"{d}: not a directory")
    if not os.access(d, os.W_OK | os.X_OK):
        raise UserError(f"{d}: directory is not writable")
    return d


def check_output_file(
    path: str | os.PathLike[str], suffixes: tuple[str, ...] | None = None
) -> Path:
    """Check, before any work is done, that an output file can be written later.

    Args:
        path: the output file.
        suffixes: allowed lower-case suffixes (e.g. ``(".png", ".pdf")``), or None for any.

    Returns:
        The path as a ``Path``.

    Raises:
        UserError: the path is a directory, its suffix is not allowed, or its directory is
            missing or not writable.
    """
    p = Path(path)
    if not p.name or p.is_dir():
        raise UserError(f"{p}: is a directory, expected a file name")
    if suffixes is not None and p.suffix.lower() not in suffixes:
        raise UserError(f"{p}: expected a file name ending in {' or '.join(suffixes)}")
    check_writable_dir(p.parent)
    if p.exists() and not os.access(p, os.W_OK):
        # os.replace would succeed anyway (it needs only the directory); refuse to be surprising.
        raise UserError(f"{p}: file exists and is not writable")
    return p
