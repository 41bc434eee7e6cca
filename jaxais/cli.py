"""Shared plumbing for the command-line scripts (``scripts/*.py``): errors and safe output.

Every script follows the same contract:

- A mistake by the user (a bad flag value, a missing or malformed world file, an output
  directory that cannot be written) ends the run with ONE line on stderr,
  ``"{prog}: error: {message}"``, and exit status 2 -- the same shape as argparse's own errors --
  and never a traceback. Ctrl-C ends it with ``"{prog}: error: interrupted"`` and status 130.
- Outputs are written atomically: to a temporary file in the target's directory, then moved
  over the target with :func:`os.replace`, so a failed or interrupted run never leaves a
  half-written file (an earlier complete file of that name survives).

Typical use::

    from jaxais.cli import UserError, atomic_write_json, main_wrapper, run_script

    @main_wrapper("evolve.py")
    def main(argv=None):
        args = parse_args(argv)
        if args.generations <= 0:
            raise UserError(f"--generations must be positive, got {args.generations}")
        ...
        atomic_write_json(args.out, results)

    if __name__ == "__main__":
        run_script(main)  # ends the process at once, without interpreter teardown

``main_wrapper`` also works as a context manager (``with main_wrapper("bench.py"): ...``).

This module imports neither JAX nor ``jaxais.envs``, so a script can parse its flags (and, for
example, set ``XLA_FLAGS``) before JAX is imported. ``jaxais.envs.WorldError`` is a
``ValueError`` and is handled as one. Set ``JAXAIS_DEBUG=1`` in the environment to let errors
propagate with their full traceback instead.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any, NoReturn

__all__ = [
    "ArgumentParser",
    "EXIT_INTERRUPTED",
    "EXIT_USAGE",
    "UserError",
    "atomic_write",
    "atomic_write_json",
    "atomic_write_text",
    "check_output_file",
    "check_writable_dir",
    "error_message",
    "fail",
    "main_wrapper",
    "run_script",
]

EXIT_USAGE = 2
"""Exit status of a user error (as argparse uses for bad flags)."""
EXIT_INTERRUPTED = 130
"""Exit status after Ctrl-C (128 + SIGINT, the shell convention)."""
DEBUG_ENV = "JAXAIS_DEBUG"
"""Environment variable: when set to a non-empty value other than 0, errors are re-raised."""


class UserError(Exception):
    """A mistake by the user, reported as one line without a traceback (exit status 2)."""


def _one_line(text: str) -> str:
    """``text`` with its lines joined: the error contract is one line on stderr."""
    return " ".join(part.strip() for part in str(text).splitlines() if part.strip())


def error_message(err: BaseException) -> str:
    """A one-line description of ``err`` suitable for ``"{prog}: error: {message}"``.

    ``OSError`` messages name the file (``out/x.png: Permission denied``); others use ``str``.
    """
    if isinstance(err, KeyboardInterrupt):
        return "interrupted"
    if isinstance(err, OSError) and err.strerror:
        where = err.filename if err.filename is not None else ""
        return _one_line(f"{where}: {err.strerror}" if where else err.strerror)
    text = _one_line(str(err))
    return text or type(err).__name__


def fail(prog: str, message: str, status: int = EXIT_USAGE) -> NoReturn:
    """Print ``"{prog}: error: {message}"`` (one line) on stderr and exit with ``status``."""
    sys.stderr.write(f"{prog}: error: {_one_line(message)}\n")
    sys.stderr.flush()
    raise SystemExit(status)


class ArgumentParser(argparse.ArgumentParser):
    """``argparse.ArgumentParser`` whose errors are one line, like every other error here.

    argparse prints a usage block before its error; a bad flag instead gives
    ``"{prog}: error: {message} (see --help)"`` and exit status 2.
    """

    def error(self, message: str) -> NoReturn:
        fail(self.prog, f"{message} (see --help)")


def _debug() -> bool:
    return os.environ.get(DEBUG_ENV, "") not in ("", "0")


class main_wrapper(contextlib.ContextDecorator):  # noqa: N801 (used like a function)
    """Turn user errors into one line on stderr and an exit status.

    Usable as a decorator (``@main_wrapper("render.py")``) or as a context manager. Handles:

    - :class:`UserError`, ``ValueError`` (bad parameter values; ``jaxais.envs.WorldError`` is
      one) and ``OSError`` (``FileNotFoundError``, ``PermissionError``, a full disk, ...):
      exit status 2;
    - ``KeyboardInterrupt``: message "interrupted", exit status 130;
    - any type in ``extra``: exit status 2.

    ``SystemExit`` (argparse's own usage errors, ``--help``) passes through untouched, as do
    other exceptions (a bug should show its traceback). With ``JAXAIS_DEBUG=1`` nothing is
    caught.

    Args:
        prog: the program name used as the message prefix, e.g. ``"render.py"``.
        extra: further exception types to report as user errors.
    """

    def __init__(self, prog: str, extra: tuple[type[BaseException], ...] = ()):
        self.prog = prog
        self.handled: tuple[type[BaseException], ...] = (UserError, ValueError, OSError, *extra)

    def __enter__(self) -> main_wrapper:
        return self

    def __exit__(self, exc_type, exc, tb) -> bool:
        if exc is None or _debug():
            return False
        if isinstance(exc, KeyboardInterrupt):
            fail(self.prog, "interrupted", EXIT_INTERRUPTED)
        if isinstance(exc, self.handled):
            fail(self.prog, error_message(exc))
        return False


def run_script(main: Callable[[], object]) -> NoReturn:
    """Run a script's ``main()`` and end the process at once, skipping interpreter teardown.

    For a script's ``if __name__ == "__main__":`` block only. Once a JAX script is done, with its
    files written and closed, Python's interpreter teardown (XLA's client, its thread pools and
    compiled programs, every module) still took 0.5-0.6 s of wall time on a 2-core CPU
    (``trials.py`` and ``evolve.py``). Here the process ends at once instead (``os._exit``) after
    flushing stdout and stderr; ``atexit`` handlers do not run.

    The exit status is 0 when ``main`` returns (what it returns is for in-process callers, e.g.
    tests, and is ignored), or that of a ``SystemExit`` it raises, as ``sys.exit`` gives it (a
    message is printed on stderr and gives 1). Other exceptions propagate as usual, with their
    traceback.
    """
    try:
        main()
        code: object = 0
    except SystemExit as stop:
        code = stop.code
    if code is None:
        status = 0
    elif isinstance(code, int):
        status = code
    else:
        print(code, file=sys.stderr)
        status = 1
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(status)


# ---------------------------------------------------------------------------------- checks


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


# ---------------------------------------------------------------------------------- writing


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
