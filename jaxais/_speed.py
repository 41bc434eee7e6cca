"""Every speed setting of jaxais, in one place (private).

The command-line scripts call :func:`setup` before JAX starts; the library never does, and no
function a researcher calls takes a speed setting. Each setting saves at least 10 % of some
script's wall time and leaves every number as it is (docs/performance.md has the measurements
and how to repeat them):

- two XLA flags for the CPU: no YNNPACK fusions (XLA hands small reductions to YNNPACK by
  default, slower than its own loops for the simulator's per-robot reductions over a few
  surfaces), and XLA's older loop emitters, which compile the task loop's many small kernels
  faster. They are set only for the jaxlib they were checked with (:data:`CHECKED_JAXLIB`):
  XLA stops a process whose ``XLA_FLAGS`` names a flag it does not know;
- one JAX CPU device per core (``cpu_device_per_core``), over which
  :mod:`jaxais.runner` shards its batches: XLA runs a batch of 30-50 robots' small
  kernels on about one core per device. The STL scripts use it; the GA does not (slower there);
- for the GA (``one_kernel_loops``), XLA compiles a while loop whose iteration touches under
  512 KiB into one function instead of dispatching its ~50 small kernels one by one on every
  iteration. The GA's numbers are the same bit for bit; in the STL's loop the one-function
  form rounds some rare step differently in the last bit, so the trials do without;
- JAX's persistent compilation cache, so a second run with the same shapes loads its compiled
  programs instead of compiling them: ``JAXAIS_CACHE_DIR`` names the directory (default
  ``~/.cache/jaxais/xla``), ``JAXAIS_CACHE_DIR=off`` turns it off.

A flag already in ``XLA_FLAGS`` (or a device count in ``JAX_NUM_CPU_DEVICES``) is left as the
user set it.
"""

from __future__ import annotations

import os
import re
from importlib.metadata import version
from pathlib import Path

XLA_FLAGS = ("--xla_cpu_experimental_ynn_fusion_type=", "--xla_cpu_use_fusion_emitters=false")
"""Added to ``XLA_FLAGS`` for every script."""
ONE_KERNEL_LOOPS = "--xla_backend_extra_options=xla_cpu_small_while_loop_byte_threshold=524288"
"""Added for ``one_kernel_loops``."""
DEVICE_COUNT = "--xla_force_host_platform_device_count"
"""Set to the usable cores for ``cpu_device_per_core``."""
CHECKED_JAXLIB = ((0, 10), (0, 11))
"""The jaxlib releases, from (inclusive) and to (exclusive), that know the flags above."""
CACHE_ENV = "JAXAIS_CACHE_DIR"
"""Environment variable: the compilation cache's directory, or ``off``."""


def setup(
    cpu_device_per_core: bool = False, one_kernel_loops: bool = False, cache: bool = True
) -> None:
    """Apply the settings; call before the first JAX computation (XLA reads its flags then).

    Args:
        cpu_device_per_core: make one JAX CPU device per usable core (the STL scripts).
        one_kernel_loops: compile small while loops into one function (``scripts/evolve.py``).
        cache: use the compilation cache (not ``scripts/bench.py``, which times compilation).
    """
    ours: list[str] = []
    release = tuple(map(int, re.match(r"(\d+)\.(\d+)", version("jaxlib")).groups()))
    if CHECKED_JAXLIB[0] <= release < CHECKED_JAXLIB[1]:
        ours += [*XLA_FLAGS, *([ONE_KERNEL_LOOPS] if one_kernel_loops else [])]
    if cpu_device_per_core and not os.environ.get("JAX_NUM_CPU_DEVICES"):
        cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
        ours.append(f"{DEVICE_COUNT}={cores or 1}")
    flags = os.environ.get("XLA_FLAGS", "").split()
    names = {flag.split("=")[0] for flag in flags}
    os.environ["XLA_FLAGS"] = " ".join(flags + [f for f in ours if f.split("=")[0] not in names])
    path = os.environ.get(CACHE_ENV, "").strip() or str(Path.home() / ".cache/jaxais/xla")
    if cache and path.lower() != "off":
        import jax

        jax.config.update("jax_compilation_cache_dir", path)
