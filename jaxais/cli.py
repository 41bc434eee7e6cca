"""The command-line layer: flags in, one library call, one-line errors out.

Imported by the entry points (``scripts/*.py``, installed as ``jaxais.scripts``) only; the
library never imports it. Every script keeps the same contract:

- A mistake by the user (a bad flag value, a missing or malformed world file, an output
  directory that cannot be written) ends the run with ONE line on stderr,
  ``"{prog}: error: {message}"``, and exit status 2 (argparse's shape), never a traceback.
- Ctrl-C (SIGINT) ends it with ``"{prog}: error: interrupted"`` and status 130, SIGTERM with
  ``"{prog}: error: terminated"`` and 143, wherever the signal lands: the handler runs
  :data:`jaxais.io.ON_SIGNAL`, removes the temporary files of writes in flight
  (:data:`jaxais.io.IN_FLIGHT`) and ends the process at once. Every output is written
  atomically (:mod:`jaxais.io`) and checkpoints are saved whole, so nothing is half-written and a
  resumable run resumes from its last checkpoint.

Typical use::

    from jaxais.cli import UserError, main_wrapper, run_script

    @main_wrapper("evolve.py")
    def main(argv=None):
        args = parse_args(argv)
        if args.generations <= 0:
            raise UserError(f"--generations must be positive, got {args.generations}")
        ...

    if __name__ == "__main__":
        run_script(main)

Scripts import JAX inside ``main``, so a bad flag is reported (and ``XLA_FLAGS`` set) before
JAX starts. Set ``JAXAIS_DEBUG=1`` to let errors propagate with their traceback instead.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import sys
import threading
from collections.abc import Callable
from typing import Any, NoReturn

from jaxais import distributed, io
from jaxais.io import (
    UserError,
    atomic_write,
    atomic_write_json,
    atomic_write_text,
    check_output_file,
    check_writable_dir,
)

__all__ = [
    "ArgumentParser",
    "EXIT_INTERRUPTED",
    "EXIT_TERMINATED",
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
EXIT_TERMINATED = 143
"""Exit status after SIGTERM (128 + SIGTERM)."""
DEBUG_ENV = "JAXAIS_DEBUG"
"""Environment variable: when set to a non-empty value other than 0, errors are re-raised."""
_STATUS = {
    signal.SIGINT: (EXIT_INTERRUPTED, "interrupted"),
    signal.SIGTERM: (EXIT_TERMINATED, "terminated"),
}


def _one_line(text: str) -> str:
    """``text`` with its lines joined: the error contract is one line on stderr."""
    return " ".join(part.strip() for part in str(text).splitlines() if part.strip())


def error_message(err: BaseException) -> str:
    """A one-line description of ``err`` for ``"{prog}: error: {message}"``.

    ``OSError`` messages name the file (``out/x.png: Permission denied``); others use ``str``.
    """
    if isinstance(err, KeyboardInterrupt):
        return "interrupted"
    if isinstance(err, OSError) and err.strerror:
        where = err.filename if err.filename is not None else ""
        return _one_line(f"{where}: {err.strerror}" if where else err.strerror)
    return _one_line(str(err)) or type(err).__name__


def _error_line(prog: str, message: str) -> str:
    """``"{prog}: error: {message}"`` as written to stderr: on a line of its own even when a
    progress bar (tqdm, which leaves the cursor at the end of its line) is on the screen."""
    bars = getattr(sys.modules.get("tqdm"), "tqdm", None)
    open_bar = any(not getattr(bar, "disable", True) for bar in getattr(bars, "_instances", ()))
    return ("\n" if open_bar else "") + f"{prog}: error: {_one_line(message)}\n"


def fail(prog: str, message: str, status: int = EXIT_USAGE) -> NoReturn:
    """Print ``"{prog}: error: {message}"`` (one line) on stderr and exit with ``status``."""
    sys.stderr.write(_error_line(prog, message))
    sys.stderr.flush()
    if distributed.ABANDONED:  # a join that timed out: the exit's teardown would hang or abort
        sys.stdout.flush()
        os._exit(status)
    raise SystemExit(status)


class ArgumentParser(argparse.ArgumentParser):
    """``argparse.ArgumentParser`` whose errors are one line: ``"{prog}: error: {message}
    (see --help)"`` and exit status 2, instead of a usage block."""

    def error(self, message: str) -> NoReturn:
        fail(self.prog, f"{message} (see --help)")


def _debug() -> bool:
    return os.environ.get(DEBUG_ENV, "") not in ("", "0")


def _signal_handler(prog: str) -> Callable[[int, Any], None]:
    """A handler that ends the process at once with the signal's one line, after the library's
    :data:`jaxais.io.ON_SIGNAL` (e.g. stopping child processes) and removing the temporary files
    of writes in flight. Nothing unwinds, so no interrupt can land half-way in
    an import, a ``__del__`` or a C extension and come out as a traceback or a crash."""

    def handler(signum: int, frame: Any) -> None:
        status, message = _STATUS[signum]
        for cleanup in reversed(list(io.ON_SIGNAL)):
            with contextlib.suppress(Exception):
                cleanup()
        for tmp in list(io.IN_FLIGHT):
            with contextlib.suppress(OSError):
                tmp.unlink()
        with contextlib.suppress(OSError):
            os.write(2, _error_line(prog, message).encode())
        os._exit(status)

    return handler


class main_wrapper(contextlib.ContextDecorator):  # noqa: N801 (used like a function)
    """Turn user errors and signals into one line on stderr and an exit status.

    Usable as a decorator (``@main_wrapper("render.py")``) or as a context manager:

    - :class:`UserError`, ``ValueError`` (bad parameter values; ``jaxais.envs.WorldError`` is
      one), ``OSError`` and any type in ``extra``: one line, exit status 2;
    - SIGINT and SIGTERM (main thread only; a signal the process started with ignored, as
      ``nohup`` does, stays ignored): one line, status 130 or 143, at once (see
      :func:`_signal_handler`). The previous handlers are restored on the way out.

    ``SystemExit`` (argparse's usage errors, ``--help``) passes through, as do other exceptions
    (a bug shows its traceback). With ``JAXAIS_DEBUG=1`` nothing is caught.
    """

    def __init__(self, prog: str, extra: tuple[type[BaseException], ...] = ()):
        self.prog = prog
        self.handled: tuple[type[BaseException], ...] = (UserError, ValueError, OSError, *extra)
        self._previous: list[dict[int, Any]] = []  # a stack: the decorated main may recurse

    def __enter__(self) -> main_wrapper:
        previous = {}
        if not _debug() and threading.current_thread() is threading.main_thread():
            handler = _signal_handler(self.prog)
            for signum in _STATUS:
                if signal.getsignal(signum) is not signal.SIG_IGN:
                    previous[signum] = signal.signal(signum, handler)
        self._previous.append(previous)
        return self

    def __exit__(self, exc_type, exc, tb) -> bool:
        for signum, handler in self._previous.pop().items():
            signal.signal(signum, handler if handler is not None else signal.SIG_DFL)
        if exc is None or _debug() or isinstance(exc, SystemExit):
            return False
        if isinstance(exc, KeyboardInterrupt):  # raised by code, not by our handler
            fail(self.prog, "interrupted", EXIT_INTERRUPTED)
        if isinstance(exc, self.handled):
            fail(self.prog, error_message(exc))
        return False


def run_script(main: Callable[[], object]) -> NoReturn:
    """Run a script's ``main()`` and exit: status 0 when it returns (its value is for in-process
    callers such as tests), or that of a ``SystemExit`` it raises."""
    main()
    raise SystemExit(0)
