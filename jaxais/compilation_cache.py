"""A persistent XLA compilation cache for the command-line scripts.

Compiling the task loop takes 5-15 s on a CPU, which is most of a short run's wall time. The
scripts (``evolve.py``, ``trials.py``, ``reproduce.py``, ``render.py``) therefore keep JAX's
persistent compilation cache on disk, so a program compiled once is loaded (well under a second)
by every later run with the same batch shapes, world, jax version and machine. A cached program
is the same XLA executable, so results are bit-for-bit those of a fresh compile; XLA's CPU
loader rejects an entry made on a machine with other CPU features, which is then compiled
afresh.

Where the cache lives, first match wins:

1. ``JAX_COMPILATION_CACHE_DIR`` (JAX's own setting) when set: JAX manages it, we leave it alone;
2. ``JAXAIS_CACHE_DIR``: a directory, or ``off`` (or empty) for no cache;
3. ``$XDG_CACHE_HOME/jaxais/xla``, else ``~/.cache/jaxais/xla``.

The library itself never turns the cache on: only the scripts call :func:`enable`.
``scripts/bench.py`` leaves it off, since it measures compile time.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Mapping
from pathlib import Path

ENV = "JAXAIS_CACHE_DIR"
"""Environment variable naming the cache directory (``off`` or empty: no cache)."""
JAX_ENV = "JAX_COMPILATION_CACHE_DIR"
"""JAX's own setting; when present it takes precedence over ours."""
_OFF = {"", "off", "0", "none", "false", "no"}


def resolve(environ: Mapping[str, str] | None = None) -> Path | None:
    """The cache directory the scripts use under ``environ`` (default ``os.environ``).

    Returns:
        The directory, or None when the cache is off or JAX's own setting governs it.
    """
    env = os.environ if environ is None else environ
    if env.get(JAX_ENV):
        return None
    if ENV in env:
        value = env[ENV].strip()
        return None if value.lower() in _OFF else Path(value).expanduser()
    base = env.get("XDG_CACHE_HOME") or str(Path("~").expanduser() / ".cache")
    return Path(base) / "jaxais" / "xla"


def enable(environ: Mapping[str, str] | None = None) -> str | None:
    """Turn on JAX's persistent compilation cache at :func:`resolve`'s directory.

    A cache is only an optimisation: a directory that cannot be created or written gives one
    warning line on stderr and the run goes on without it.

    Returns:
        The directory in use (JAX's own when ``JAX_COMPILATION_CACHE_DIR`` is set), or None.
    """
    env = os.environ if environ is None else environ
    if env.get(JAX_ENV):
        return env[JAX_ENV]
    path = resolve(env)
    if path is None:
        return None
    try:
        path.mkdir(parents=True, exist_ok=True)
        if not os.access(path, os.W_OK | os.X_OK):
            raise PermissionError(f"{path} is not writable")
    except OSError as err:
        reason = err.strerror or str(err)
        print(
            f"warning: no compilation cache ({reason}: {path}); set {ENV} to a writable "
            f"directory or to 'off'",
            file=sys.stderr,
        )
        return None
    import jax

    jax.config.update("jax_compilation_cache_dir", str(path))
    return str(path)
