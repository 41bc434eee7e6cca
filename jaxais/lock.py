"""One writer per output folder: a lock file that says who writes there, kept fresh by a heartbeat.

Every run that writes a folder it can resume (:func:`jaxais.io.open_run`: seeds, reproduce,
sweep, ablate, train_baseline; evolve's checkpoints, :class:`jaxais.checkpointing.GACheckpointer`)
holds ``FOLDER/.jaxais-lock`` while it writes: JSON with the host, the PID and the time of the
last heartbeat, rewritten every :data:`HEARTBEAT_S` by a daemon thread. Another process refuses
the folder in one line while the lock is live, and takes it over once it is stale:

- :data:`STALE_S` (3 heartbeats) after its last heartbeat, from any host (a job preempted on one
  node resumes on another a minute later; the hosts' clocks must agree to within a minute);
- at once when it names this host and a PID that is no longer running (``kill -9``);
- at once when it names this very process (an earlier run in it that raised).

The lock goes when the run completes, when the call that took it returns or raises (the drivers
are :func:`scoped`: a notebook's Ctrl-C does not keep the folder), when the process exits, and
on SIGINT/SIGTERM (the file is in :data:`jaxais.io.IN_FLIGHT`, which the scripts' signal handler
removes). A process stopped for
longer than :data:`STALE_S` (``kill -STOP``, a suspended laptop) may find its lock taken over;
its heartbeat then says so on stderr and stops.
"""

from __future__ import annotations

import atexit
import contextlib
import functools
import json
import os
import socket
import sys
import tempfile
import threading
import time
import uuid
from collections.abc import Callable
from pathlib import Path
from typing import Any, ParamSpec, TypeVar

from jaxais import children, io

__all__ = ["HEARTBEAT_S", "NAME", "STALE_S", "FolderLock", "acquire", "scoped"]

P, R = ParamSpec("P"), TypeVar("R")

NAME = ".jaxais-lock"  # one dot: open_run's sweep of cut temporary files (".x.y") leaves it
HEARTBEAT_S = 20.0  # how often a holder rewrites its lock
STALE_S = 3 * HEARTBEAT_S  # a lock this long without a heartbeat is taken over
_HELD: set[FolderLock] = set()  # this process's locks, released at exit


def _read(path: Path) -> dict[str, Any] | None:
    """The lock's record; {} if unreadable (being created, or damaged); None if there is none."""
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return None
    except (OSError, ValueError):
        return {}
    return doc if isinstance(doc, dict) else {}


def holder(path: Path, record: dict[str, Any]) -> str | None:
    """Who holds the lock ``record`` (of the file ``path``) in words, or None if it is stale."""
    host, pid, beat = record.get("host"), record.get("pid"), record.get("heartbeat")
    if not isinstance(beat, int | float) or isinstance(beat, bool):
        with contextlib.suppress(OSError):  # a lock being created, or a damaged one: its age
            beat = path.stat().st_mtime
    if not isinstance(beat, int | float):
        return None
    mine = host == socket.gethostname() and isinstance(pid, int)
    if mine and (pid == os.getpid() or not children.pid_alive(pid)):
        return None
    age = time.time() - beat
    if age > STALE_S:
        return None
    who = f"PID {pid} on {host}" if host else "a process (its lock file is unreadable)"
    return f"{who}, last heartbeat {max(age, 0):.0f} s ago"


class FolderLock:
    """A held lock on ``folder`` (see the module); :meth:`release` gives it up."""

    def __init__(self, folder: Path) -> None:
        self.folder, self.path = folder, folder / NAME
        self.token = uuid.uuid4().hex  # tells this holder from an earlier one in the same PID
        self.thread = threading.get_ident()  # the thread that took it (scoped)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def record(self) -> dict[str, Any]:
        return {"host": socket.gethostname(), "pid": os.getpid(), "token": self.token,
                "heartbeat": time.time(), "stale_after_s": STALE_S}  # fmt: skip

    def ours(self) -> bool:
        return (_read(self.path) or {}).get("token") == self.token

    def _beat(self) -> None:
        while not self._stop.wait(HEARTBEAT_S):
            if not self.ours():
                io.IN_FLIGHT.discard(self.path)  # not ours to remove on a signal any more
                sys.stderr.write(
                    f"jaxais: warning: {self.path}: lock taken over by another process (this one "
                    "was stopped too long); it writes here now\n"
                )
                return
            with contextlib.suppress(OSError):  # a full disk: the next beat tries again
                io.atomic_write_json(self.path, self.record(), indent=None)

    def start(self) -> None:
        _HELD.add(self)
        io.IN_FLIGHT.add(self.path)  # removed by the scripts' signal handler (jaxais.cli)
        self._thread = threading.Thread(target=self._beat, name="jaxais-lock", daemon=True)
        self._thread.start()

    def release(self) -> None:
        """Stop the heartbeat and remove the lock file (if it is still this holder's)."""
        self._stop.set()
        _HELD.discard(self)
        io.IN_FLIGHT.discard(self.path)
        if self.ours():
            with contextlib.suppress(OSError):
                self.path.unlink()


def _create(path: Path, record: dict[str, Any]) -> None:
    """Write ``record`` to ``path`` unless it exists (FileExistsError): one winner of a race."""
    fd = os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
    with os.fdopen(fd, "w", encoding="utf-8") as f:
        f.write(json.dumps(record))
        f.flush()
        os.fsync(f.fileno())


def _take_over(path: Path, judged: dict[str, Any]) -> None:
    """Remove the stale lock ``judged`` unless another process replaced it meanwhile."""
    fd, aside = tempfile.mkstemp(dir=path.parent, prefix=f"{NAME}.stale.")
    os.close(fd)
    try:
        os.replace(path, aside)  # atomic: of two takers, one moves the stale lock
    except FileNotFoundError:
        return
    finally:
        if _read(Path(aside)) != judged:  # a fresh lock was moved: put it back
            with contextlib.suppress(OSError):
                os.link(aside, path)
        with contextlib.suppress(OSError):
            os.unlink(aside)


def acquire(folder: str | os.PathLike[str]) -> FolderLock:
    """Lock the existing directory ``folder`` for this process, taking over a stale lock; a
    one-line UserError naming the holder if another live process holds it."""
    lock = FolderLock(Path(folder))
    for _ in range(5):  # a few rounds of a race with other takers
        try:
            _create(lock.path, lock.record())
        except FileExistsError:
            held = _read(lock.path)
            if held is None:
                continue  # released meanwhile
            who = holder(lock.path, held)
            if who is not None:
                raise io.UserError(
                    f"{lock.folder}: another process is writing here ({who}); wait for it to "
                    f"end or stop it (its lock {NAME} is stale {STALE_S:.0f} s after its last "
                    "heartbeat, at once if its process on this host has ended)"
                ) from None
            _take_over(lock.path, held)
            continue
        lock.start()
        return lock
    raise io.UserError(f"{lock.folder}: could not take its lock {NAME}: other processes race")


def scoped(fn: Callable[P, R]) -> Callable[P, R]:
    """Decorate a driver: the locks it takes (in its thread) go when it returns or raises."""

    @functools.wraps(fn)
    def call(*args: P.args, **kwargs: P.kwargs) -> R:
        me = threading.get_ident()
        before = {lock for lock in _HELD if lock.thread == me}
        try:
            return fn(*args, **kwargs)
        finally:
            for lock in [lock for lock in list(_HELD) if lock.thread == me]:
                if lock not in before:
                    lock.release()

    return call


@atexit.register
def _release_all() -> None:
    for lock in list(_HELD):
        lock.release()
