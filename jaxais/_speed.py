"""Every speed setting of jaxais, in one place (private; docs/performance.md measures each).

The scripts call :func:`setup` before JAX starts; the library never does. Each setting saves at
least 10 % of some script's wall time and leaves every number as it is:

- two XLA CPU flags (no YNNPACK fusions; the older loop emitters, which compile the loop's many
  small kernels faster), only for the jaxlib they were checked with (:data:`CHECKED_JAXLIB`);
- one CPU device per core for the STL scripts, over which :mod:`jaxais.runner` shards batches;
- JAX's persistent compilation cache in ``$JAXAIS_CACHE_DIR`` (default ``~/.cache/jaxais/xla``;
  ``off`` turns it off). A folder that cannot be made or written turns it off with one line on
  stderr; JAX's own warnings about a cache entry it could not read or write (two lines each,
  for every program) become one line, once, as the run goes on without it.

A flag already in ``XLA_FLAGS`` (or ``JAX_NUM_CPU_DEVICES``) is left as the user set it.
"""

from __future__ import annotations

import os
import re
import sys
import tempfile
import warnings
from collections.abc import Callable
from importlib.metadata import version
from pathlib import Path

XLA_FLAGS = ("--xla_cpu_experimental_ynn_fusion_type=", "--xla_cpu_use_fusion_emitters=false")
DEVICE_COUNT = "--xla_force_host_platform_device_count"
CHECKED_JAXLIB = ((0, 10), (0, 11))  # jaxlib releases [from, to) that know the flags above
CACHE_ENV = "JAXAIS_CACHE_DIR"


def setup(cpu_device_per_core: bool = False, cache: bool = True) -> None:
    """Apply the settings before the first JAX computation (XLA reads its flags then);
    ``cache=False`` for the bench, which times compilation."""
    ours: list[str] = []
    release = tuple(map(int, re.match(r"(\d+)\.(\d+)", version("jaxlib")).groups()))
    if CHECKED_JAXLIB[0] <= release < CHECKED_JAXLIB[1]:
        ours += list(XLA_FLAGS)
    if cpu_device_per_core and not os.environ.get("JAX_NUM_CPU_DEVICES"):
        cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
        ours.append(f"{DEVICE_COUNT}={cores or 1}")
    flags = os.environ.get("XLA_FLAGS", "").split()
    names = {flag.split("=")[0] for flag in flags}
    os.environ["XLA_FLAGS"] = " ".join(flags + [f for f in ours if f.split("=")[0] not in names])
    path = os.environ.get(CACHE_ENV, "").strip() or str(Path.home() / ".cache/jaxais/xla")
    if cache and path.lower() != "off" and _usable(path):
        import jax

        jax.config.update("jax_compilation_cache_dir", path)
        warnings.showwarning = _one_line_cache_warnings(warnings.showwarning)


def _say(text: str) -> None:
    sys.stderr.write(f"jaxais: warning: {' '.join(text.split())}\n")


def _usable(path: str) -> bool:
    """Whether the cache folder ``path`` exists (made if not) and takes files; else one line."""
    try:
        Path(path).mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=path):
            return True
    except OSError as err:
        _say(f"compilation cache off: {path}: {err.strerror or err} (set {CACHE_ENV} to a "
             "writable folder, or to off)")  # fmt: skip
        return False


def _one_line_cache_warnings(show: Callable[..., None]) -> Callable[..., None]:
    """``warnings.showwarning`` with JAX's cache-entry warnings as one line, the first only."""
    said = []

    def showwarning(message, category, filename, lineno, file=None, line=None):
        text = str(message)
        if "persistent compilation cache" not in text:
            return show(message, category, filename, lineno, file, line)
        if not said:
            said.append(text)
            _say(f"{text[:300]} (the run goes on without the cache; later cache errors are not "
                 f"shown; {CACHE_ENV}=off turns it off)")  # fmt: skip
        return None

    return showwarning
