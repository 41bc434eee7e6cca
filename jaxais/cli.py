"""The command-line layer (imported by ``scripts/*.py`` only): flags in, one call, one line out.

- A user's mistake (bad flag value, bad world file, unwritable output) ends the run with ONE
  line on stderr, ``"{prog}: error: {message}"``, and exit status 2, never a traceback.
- SIGINT ends it with ``"{prog}: error: interrupted"`` and 130, SIGTERM with ``terminated`` and
  143, wherever the signal lands: the handler runs :data:`jaxais.io.ON_SIGNAL`, removes the temp
  files of writes in flight (:data:`jaxais.io.IN_FLIGHT`) and exits at once. Outputs are atomic
  and checkpoints whole, so nothing is half-written and a resumable run resumes.
- A multi-process run whose collective fails (another process died) ends with one line too.
- A script started by another (:mod:`jaxais.children`) ends like a SIGTERM when its parent dies,
  even by ``kill -9``: no orphan keeps writing into a folder that a ``--resume`` takes over.
- I/O errors name their file (``out/x.json: No space left on device``).

Scripts wrap ``main`` in ``@main_wrapper("name.py")``, run it with :func:`run_script` and import
JAX inside ``main`` (a bad flag is reported before JAX starts). ``JAXAIS_DEBUG=1`` re-raises.
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

from jaxais import children, distributed, io

# The scripts' (and tests') names for these, with the CLI's own.
from jaxais.io import (  # noqa: F401
    UserError,
    atomic_write,
    atomic_write_json,
    check_output_file,
    check_writable_dir,
)

EXIT_USAGE, EXIT_INTERRUPTED, EXIT_TERMINATED = 2, 130, 143  # argparse's; 128 + the signal
DEBUG_ENV = "JAXAIS_DEBUG"  # set (not to 0): errors propagate with their traceback
_WATCHING: list[Any] = []  # the parent's watcher (jaxais.children), started once per process
_STATUS = {
    signal.SIGINT: (EXIT_INTERRUPTED, "interrupted"),
    signal.SIGTERM: (EXIT_TERMINATED, "terminated"),
}


def remake_command(prog: str, argv: list[str] | None = None) -> str:
    """The command line a run records (its ``run.json``, its config): ``prog`` and its arguments
    (``argv``, default the process's) without ``--resume``, so a resumed run records the command
    that makes it whole."""
    words = sys.argv[1:] if argv is None else argv
    return f"{prog} " + " ".join(w for w in words if w != "--resume")


def add_ledger_arguments(p: argparse.ArgumentParser, jobs: str) -> None:
    """The flags of the scripts that run the protocol over LTL seeds (seeds.py, robustness.py):
    --out, --resume, --seeds, --first, --trials and --jobs (``jobs``: what runs side by side)."""
    # fmt: off
    p.add_argument("--out", required=True, help="output directory (missing or empty)")
    p.add_argument("--resume", action="store_true", help="finish the interrupted run in --out")
    p.add_argument("--seeds", type=int, default=10, help="how many LTL seeds (default 10)")
    p.add_argument("--first", type=int, default=0, help="the first seed (default 0)")
    p.add_argument("--trials", type=int, default=None,
                   help="trials per system and world (default: the paper's)")
    p.add_argument("--jobs", type=int, default=None,
                   help=f"{jobs} side by side (default: one per core)")
    # fmt: on


def _one_line(text: str) -> str:
    """``text`` with its lines joined: the error contract is one line on stderr."""
    return " ".join(part.strip() for part in str(text).splitlines() if part.strip())


def error_message(err: BaseException) -> str:
    """``err`` in one line; an ``OSError`` names its file (``out/x.png: Permission denied``)."""
    if isinstance(err, OSError) and err.strerror:
        return _one_line(f"{err.filename}: {err.strerror}" if err.filename else err.strerror)
    return _one_line(str(err)) or type(err).__name__


def _error_line(prog: str, message: str) -> str:
    """``"{prog}: error: {message}"`` for stderr, on a line of its own under an open tqdm bar."""
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
    """An ``argparse.ArgumentParser`` whose errors are one line (``... (see --help)``), not a
    usage block."""

    def error(self, message: str) -> NoReturn:
        fail(self.prog, f"{message} (see --help)")


def _debug() -> bool:
    return os.environ.get(DEBUG_ENV, "") not in ("", "0")


class main_wrapper(contextlib.ContextDecorator):  # noqa: N801 (used like a function)
    """Decorator or context manager: ``ValueError`` (``UserError``, ``WorldError``), ``OSError`` and
    ``extra`` types give one line and status 2; SIGINT/SIGTERM (main thread; one ignored at start,
    as under ``nohup``, stays ignored) one line and 130/143. Other exceptions (bugs) and
    ``SystemExit`` pass through; ``JAXAIS_DEBUG=1`` catches nothing."""

    def __init__(self, prog: str, extra: tuple[type[BaseException], ...] = ()):
        self.prog = prog
        self.handled: tuple[type[BaseException], ...] = (ValueError, OSError, *extra)
        self._previous: list[dict[int, Any]] = []  # a stack: the decorated main may recurse

    def __enter__(self) -> main_wrapper:
        previous = {}
        if not _WATCHING:
            _WATCHING.append(children.watch_parent(self._on_orphaned))
        distributed.ON_LOST[0] = lambda message: io.abandon(_error_line(self.prog, message), 2)
        if not _debug() and threading.current_thread() is threading.main_thread():
            for signum in _STATUS:
                if signal.getsignal(signum) is not signal.SIG_IGN:
                    previous[signum] = signal.signal(signum, self._on_signal)
        self._previous.append(previous)
        return self

    def _on_signal(self, signum: int, frame: Any) -> None:
        """End the process at once with the signal's line (:func:`jaxais.io.abandon`): nothing
        unwinds, so no interrupt lands half-way in an import, a ``__del__`` or a C extension as a
        traceback or a crash."""
        status, message = _STATUS[signum]
        io.abandon(_error_line(self.prog, message), status)

    def _on_orphaned(self) -> None:
        """The parent process is gone (killed): end as its SIGTERM would have ended us."""
        io.abandon(_error_line(self.prog, "its parent process ended; stopped"), EXIT_TERMINATED)

    def __exit__(self, exc_type, exc, tb) -> bool:
        for signum, handler in self._previous.pop().items():
            signal.signal(signum, handler if handler is not None else signal.SIG_DFL)
        if exc is None or _debug() or isinstance(exc, SystemExit):
            return False
        if isinstance(exc, KeyboardInterrupt):  # raised by code, not by our handler
            fail(self.prog, "interrupted", EXIT_INTERRUPTED)
        if distributed.lost_peer(exc):
            fail(self.prog, f"{distributed.lost()} ({error_message(exc)[:200]})")
        if isinstance(exc, self.handled):
            fail(self.prog, error_message(exc))
        return False


def run_script(main: Callable[[], object]) -> NoReturn:
    """Run a script's ``main()`` and exit 0 (its value is for in-process callers: tests)."""
    main()
    raise SystemExit(0)
