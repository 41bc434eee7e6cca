"""Child processes that end with their parent, however the parent ends (even ``kill -9``).

A script that runs another (``seeds.py`` its ``evolve.py`` and ``reproduce.py``, ``reproduce.py
--evolve`` its ``evolve.py``, the bench its timed runs) starts it with :func:`popen` or
:func:`run`. Two mechanisms, so that no orphan keeps writing into a folder a ``--resume`` is
about to take over:

- on Linux, ``prctl(PR_SET_PDEATHSIG)``: the kernel sends the child SIGTERM the moment the
  thread that started it ends (SIGKILL where the parent ignores SIGTERM, as the child would).
  The starting thread waits for its child, so it outlives it unless the process dies;
- everywhere, :data:`PARENT_ENV` names the parent's PID; a child that runs
  :func:`watch_parent` (every script does, in :class:`jaxais.cli.main_wrapper`) checks once a
  :data:`POLL_S` that its parent is still its parent, and ends itself like a SIGTERM otherwise.
"""

from __future__ import annotations

import ctypes
import functools
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

__all__ = ["PARENT_ENV", "POLL_S", "pid_alive", "popen", "run", "watch_parent"]

PARENT_ENV = "JAXAIS_PARENT_PID"  # the PID of the process that started this one
POLL_S = 1.0  # how often a child checks that its parent lives
PR_SET_PDEATHSIG = 1  # <linux/prctl.h>


def _libc_prctl() -> Callable[..., int] | None:
    """libc's ``prctl``, or None off Linux (or where it cannot be loaded)."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        return ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):
        return None


_PRCTL = _libc_prctl()


def _options(kwargs: dict[str, Any]) -> dict[str, Any]:
    env = dict(os.environ if kwargs.get("env") is None else kwargs["env"])
    env[PARENT_ENV] = str(os.getpid())
    if _PRCTL is not None and kwargs.get("preexec_fn") is None:
        # SIGKILL where SIGTERM is ignored here (and so in the child, which inherits it).
        ignored = signal.getsignal(signal.SIGTERM) is signal.SIG_IGN
        sig = int(signal.SIGKILL if ignored else signal.SIGTERM)
        # Run between fork and exec: one C call, decided here (no Python lock to take there).
        kwargs["preexec_fn"] = functools.partial(_PRCTL, PR_SET_PDEATHSIG, sig, 0, 0, 0)
    return kwargs | {"env": env}


def popen(cmd: list[str], **kwargs: Any) -> subprocess.Popen:
    """``subprocess.Popen(cmd, **kwargs)`` for a child that ends with this process."""
    return subprocess.Popen(cmd, **_options(kwargs))


def run(cmd: list[str], **kwargs: Any) -> subprocess.CompletedProcess:
    """``subprocess.run(cmd, **kwargs)`` for a child that ends with this process."""
    return subprocess.run(cmd, **_options(kwargs))


def pid_alive(pid: int) -> bool:
    """Whether process ``pid`` runs (a zombie, ended but not yet reaped, does not)."""
    try:
        os.kill(pid, 0)
    except (ProcessLookupError, OverflowError, ValueError):
        return False
    except PermissionError:  # another user's process
        pass
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return True  # no /proc (off Linux): as os.kill said
    return state not in ("Z", "X")


def watch_parent(on_orphaned: Callable[[], object]) -> threading.Thread | None:
    """If this process was started by :func:`popen` or :func:`run` (:data:`PARENT_ENV`), call
    ``on_orphaned`` (which ends the process) from a daemon thread once the parent is gone; the
    thread, or None when there is nothing to watch (no parent named, or the variable was
    inherited from a grandparent that lives)."""
    try:
        parent = int(os.environ.get(PARENT_ENV, ""))
    except ValueError:
        return None
    if os.getppid() != parent and pid_alive(parent):
        return None  # not started by it: the variable came through another process

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(POLL_S)
        on_orphaned()

    thread = threading.Thread(target=watch, name="jaxais-watch-parent", daemon=True)
    thread.start()
    return thread
