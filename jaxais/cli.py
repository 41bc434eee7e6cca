"""Shared plumbing for the command-line scripts (``scripts/*.py``): errors and safe output.

Every script follows the same contract:

- A mistake by the user (a bad flag value, a missing or malformed world file, an output
  directory that cannot be written) ends the run with ONE line on stderr,
  ``"{prog}: error: {message}"``, and exit status 2 -- the same shape as argparse's own errors --
  and never a traceback. Ctrl-C (SIGINT) ends it with ``"{prog}: error: interrupted"`` and
  status 130, SIGTERM with ``"{prog}: error: terminated"`` and status 143, wherever the signal
  lands (see :class:`main_wrapper`).
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

import _thread
import argparse
import contextlib
import functools
import os
import signal
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NoReturn

from jaxais.io import atomic_write, atomic_write_json, atomic_write_text

__all__ = [
    "ArgumentParser",
    "EXIT_INTERRUPTED",
    "EXIT_TERMINATED",
    "EXIT_USAGE",
    "Terminated",
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


class UserError(Exception):
    """A mistake by the user, reported as one line without a traceback (exit status 2)."""


class Terminated(KeyboardInterrupt):
    """Raised in the main thread by SIGTERM while a script runs. A ``KeyboardInterrupt``, so
    that it unwinds like Ctrl-C (a file being written is removed, not left half-written)."""


def _one_line(text: str) -> str:
    """``text`` with its lines joined: the error contract is one line on stderr."""
    return " ".join(part.strip() for part in str(text).splitlines() if part.strip())


def error_message(err: BaseException) -> str:
    """A one-line description of ``err`` suitable for ``"{prog}: error: {message}"``.

    ``OSError`` messages name the file (``out/x.png: Permission denied``); others use ``str``.
    """
    if isinstance(err, Terminated):
        return "terminated"
    if isinstance(err, KeyboardInterrupt):
        return "interrupted"
    if isinstance(err, OSError) and err.strerror:
        where = err.filename if err.filename is not None else ""
        return _one_line(f"{where}: {err.strerror}" if where else err.strerror)
    text = _one_line(str(err))
    return text or type(err).__name__


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


# ---------------------------------------------------------------------------------- signals
#
# Python's own SIGINT handler raises KeyboardInterrupt wherever the main thread happens to be.
# Landing in the import of a C extension (numpy's or jaxlib's, which the scripts import lazily
# inside main), it comes out as an ImportError with a traceback printed along the way, or even
# crashes the interpreter; in a __del__ or a gc callback (JAX has one) it is printed with a
# traceback and dropped; and SIGTERM kills the process outright. While a script runs
# (run_script, main_wrapper) both signals go to _on_signal instead. It records the signal and
# raises KeyboardInterrupt (or Terminated) -- but not inside an import or a __del__: there it
# only records it, and a timer delivers the signal again every REDELIVER_S until that is over
# (MAX_HOLD_S at most). An interrupt dropped all the same (in a callback) reaches
# sys.unraisablehook, where _on_unraisable delivers it again. Whatever exception the interrupt
# becomes where it lands, the wrapper reports the recorded signal in one line.

REDELIVER_S = 0.02
"""How often a signal held back during an import is delivered again, s."""
MAX_HOLD_S = 10.0
"""The longest a signal is held back (code run by an import, not an import, may take long)."""


class _SignalState:
    """What the handlers know, process-wide (signals are handled in the main thread only)."""

    prog = ""
    """The running script's name, for a message printed from the handler itself."""
    depth = 0
    """Nesting of main_wrapper (and run_script) around the running code."""
    received: int | None = None
    """The first SIGINT or SIGTERM since the outermost wrapper started."""
    held = False
    """The received signal is held back (to be delivered again) and has not been raised yet."""
    held_since = 0.0
    """When it was first held back (``time.monotonic``)."""
    armed = False
    """A timer is about to deliver the held signal again."""
    leaving = False
    """A one-line exit is under way: further signals are ignored."""


_SIGNALS = (signal.SIGINT, signal.SIGTERM)
_STATUS = {
    signal.SIGINT: (EXIT_INTERRUPTED, "interrupted"),
    signal.SIGTERM: (EXIT_TERMINATED, "terminated"),
}


def _must_hold(frame: Any) -> bool:
    """Whether an interrupt raised in ``frame`` would do harm or be lost: inside an import
    (importlib's frames are on the stack), a ``__del__`` or :func:`_on_unraisable`."""
    while frame is not None:
        code = frame.f_code
        if code.co_filename.startswith("<frozen importlib") or code.co_name == "__del__":
            return True
        if code is _on_unraisable.__code__:
            return True
        frame = frame.f_back
    return False


def _deliver_again(signum: int, delay: float) -> None:
    """Deliver ``signum`` to the main thread again after ``delay`` s, to :func:`_on_signal`
    (once: a signal already on its way again is not sent twice)."""
    state = _SignalState
    if not state.held:
        state.held, state.held_since = True, time.monotonic()
    if state.armed:
        return
    state.armed = True

    def fire() -> None:
        state.armed = False
        if state.held:  # not raised meanwhile by another delivery
            _thread.interrupt_main(signum)

    timer = threading.Timer(delay, fire)
    timer.daemon = True
    timer.start()


def _on_signal(signum: int, frame: Any) -> None:
    state = _SignalState
    if state.leaving:
        return
    if state.received is not None and not state.held:
        # A second signal while the first unwinds: leave at once.
        _leave_now(signum)
    if state.received is None:
        state.received = signum
    patient = not state.held or time.monotonic() - state.held_since < MAX_HOLD_S
    if patient and _must_hold(frame):
        _deliver_again(state.received, REDELIVER_S)
        return
    state.held = False
    raise Terminated if state.received == signal.SIGTERM else KeyboardInterrupt


def _leave_now(signum: int) -> NoReturn:
    """End the process at once with the signal's one line (no unwinding, no teardown)."""
    _SignalState.leaving = True
    status, message = _STATUS[signum]
    try:
        os.write(2, _error_line(_SignalState.prog, message).encode())
    finally:
        os._exit(status)


def _on_unraisable(unraisable: Any, previous: Callable[[Any], object]) -> None:
    """An interrupt raised where Python can only print it and carry on (a weakref or gc
    callback, such as JAX's ``_xla_gc_callback``): deliver the signal again, to land in ordinary
    code. Others go to ``previous``, the hook that was there before."""
    state = _SignalState
    if (
        isinstance(unraisable.exc_value, KeyboardInterrupt)
        and state.received is not None
        and state.depth > 0
        and not state.leaving
    ):
        _deliver_again(state.received, REDELIVER_S)
        return
    previous(unraisable)


@dataclass
class _Installed:
    """What :func:`_install_handlers` replaced, for :func:`_restore_handlers`."""

    signals: dict[int, Any] = field(default_factory=dict)
    unraisable: tuple[Callable[[Any], object], Callable[[Any], object]] | None = None
    """(our hook, the one it replaced), when this installation set one."""


def _install_handlers(prog: str) -> _Installed:
    """Route SIGINT and SIGTERM to :func:`_on_signal` (main thread only; a signal the process
    started with ignored, as ``nohup`` and background jobs do, stays ignored), and interrupts
    that Python drops to :func:`_on_unraisable`.

    Returns:
        What was replaced, to give back with :func:`_restore_handlers`.
    """
    state = _SignalState
    installed = _Installed()
    if state.depth == 0:
        state.received, state.held, state.leaving = None, False, False
        previous = sys.unraisablehook
        hook = functools.partial(_on_unraisable, previous=previous)
        sys.unraisablehook = hook
        installed.unraisable = (hook, previous)
    state.depth += 1
    state.prog = prog
    if threading.current_thread() is not threading.main_thread():
        return installed
    for signum in _SIGNALS:
        current = signal.getsignal(signum)
        if current is not signal.SIG_IGN and current is not _on_signal:
            installed.signals[signum] = signal.signal(signum, _on_signal)
    return installed


def _restore_handlers(installed: _Installed) -> None:
    """Undo :func:`_install_handlers` (a handler someone else set since then stays)."""
    _SignalState.depth = max(_SignalState.depth - 1, 0)
    for signum, previous in installed.signals.items():
        if signal.getsignal(signum) is _on_signal:
            signal.signal(signum, previous if previous is not None else signal.SIG_DFL)
    if installed.unraisable is not None and sys.unraisablehook is installed.unraisable[0]:
        sys.unraisablehook = installed.unraisable[1]


def _interrupt_of(exc: BaseException | None) -> tuple[int, str] | None:
    """(status, message) when ``exc`` ends a run that a signal interrupted, else None.

    A signal received while the wrapper ran counts whatever exception it became (an
    ImportError, a RuntimeError from C++ code); otherwise an interrupt anywhere in the chain.
    """
    if exc is None:
        return None
    if _SignalState.received is not None and _SignalState.depth > 0:
        return _STATUS[_SignalState.received]
    seen: set[int] = set()
    while exc is not None and id(exc) not in seen:
        seen.add(id(exc))
        if isinstance(exc, Terminated):
            return _STATUS[signal.SIGTERM]
        if isinstance(exc, KeyboardInterrupt):
            return _STATUS[signal.SIGINT]
        exc = exc.__cause__ or exc.__context__
    return None


class main_wrapper(contextlib.ContextDecorator):  # noqa: N801 (used like a function)
    """Turn user errors into one line on stderr and an exit status.

    Usable as a decorator (``@main_wrapper("render.py")``) or as a context manager. Handles:

    - :class:`UserError`, ``ValueError`` (bad parameter values; ``jaxais.envs.WorldError`` is
      one) and ``OSError`` (``FileNotFoundError``, ``PermissionError``, a full disk, ...):
      exit status 2;
    - Ctrl-C (SIGINT, ``KeyboardInterrupt``): message "interrupted", exit status 130; SIGTERM
      (:class:`Terminated`): "terminated", 143;
    - any type in ``extra``: exit status 2.

    While it runs (in the main thread), SIGINT and SIGTERM raise ``KeyboardInterrupt`` and
    :class:`Terminated` through a handler of its own, which records the signal: whatever the
    interrupt turns into where it lands (an ``ImportError`` when it hits the import of a C
    extension, say), the run ends with the signal's one line. An interrupt dropped by Python (in a
    ``__del__``) is delivered again; a second signal while the first unwinds ends the process at
    once, with the same line. The previous handlers are restored on the way out.

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
        self._installed: list[_Installed] = []  # a stack: the decorated main may recurse

    def __enter__(self) -> main_wrapper:
        self._installed.append(_install_handlers(self.prog))
        return self

    def __exit__(self, exc_type, exc, tb) -> bool:
        interrupt = _interrupt_of(exc)
        debug = _debug()
        if exc is not None and not debug and (interrupt or isinstance(exc, self.handled)):
            _SignalState.leaving = True  # the one line is coming: no signal may cut it short
        _restore_handlers(self._installed.pop())
        if exc is None or debug or isinstance(exc, SystemExit):
            return False
        if interrupt is not None:
            status, message = interrupt
            fail(self.prog, message, status)
        if isinstance(exc, self.handled):
            fail(self.prog, error_message(exc))
        return False


def run_script(main: Callable[[], object]) -> NoReturn:
    """Run a script's ``main()`` and end the process at once, skipping interpreter teardown.

    For a script's ``if __name__ == "__main__":`` block only. Once a JAX script is done, with its
    files written and closed, Python's interpreter teardown (XLA's client, its thread pools and
    compiled programs, every module) still takes a noticeable part of a second
    (docs/performance.md). Here the process ends at once instead (``os._exit``) after flushing
    stdout and stderr; ``atexit`` handlers do not run.

    The exit status is 0 when ``main`` returns (what it returns is for in-process callers, e.g.
    tests, and is ignored), or that of a ``SystemExit`` it raises, as ``sys.exit`` gives it (a
    message is printed on stderr and gives 1). SIGINT and SIGTERM are handled from here on as
    :class:`main_wrapper` handles them, also outside ``main``'s own wrapper (one line, status 130
    or 143). Other exceptions propagate as usual, with their traceback.
    """
    prog = os.path.basename(sys.argv[0]) or "python"
    _install_handlers(prog)  # never restored: the process ends here
    try:
        main()
        code: object = 0
    except SystemExit as stop:
        code = stop.code
    except BaseException as err:
        interrupt = _interrupt_of(err)
        if interrupt is None or _debug():
            raise
        _SignalState.leaving = True
        status, message = interrupt
        sys.stderr.write(_error_line(prog, message))
        code = status
    _SignalState.leaving = True  # done: a late signal changes nothing
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
