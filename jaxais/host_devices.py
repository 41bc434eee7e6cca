"""One JAX CPU device per core for the command-line scripts, so a batch of runs uses every core.

XLA's CPU backend runs one program on one device, and the task loop's small per-iteration
kernels (a batch of 30-50 robots) keep about one core busy. The scripts therefore split the CPU
into one JAX device per usable core before JAX starts, and :func:`jaxais.episode.rollout`
shards its batch of runs over those devices (plain ``jax.sharding``: the runs are independent,
so every run's numbers are bit for bit those of a one-device run). On a GPU or TPU machine the
default devices are the accelerators and this setting changes nothing.

How many CPU devices, first match wins:

1. JAX's own settings (``JAX_NUM_CPU_DEVICES``, or ``--xla_force_host_platform_device_count`` in
   ``XLA_FLAGS``) when set: JAX applies them, we leave them alone;
2. ``JAXAIS_CPU_DEVICES``: a positive integer (``1`` turns sharding off);
3. the number of cores this process may use.

The library never changes the device count by itself: only the scripts call :func:`enable`,
before their first JAX computation.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Mapping

ENV = "JAXAIS_CPU_DEVICES"
"""Environment variable: how many JAX CPU devices the scripts make (default: usable cores)."""
JAX_ENV = "JAX_NUM_CPU_DEVICES"
XLA_FLAG = "--xla_force_host_platform_device_count"


class DeviceCountError(ValueError):
    """``JAXAIS_CPU_DEVICES`` is not a positive integer (the message is one line)."""


def usable_cores() -> int:
    """Cores this process may run on (its CPU affinity where the OS reports one)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def resolve(environ: Mapping[str, str] | None = None) -> int | None:
    """The CPU device count the scripts ask for, or None where JAX's own setting governs.

    Raises:
        DeviceCountError: ``JAXAIS_CPU_DEVICES`` is set to something other than a positive int.
    """
    env = os.environ if environ is None else environ
    if env.get(JAX_ENV) or XLA_FLAG in env.get("XLA_FLAGS", ""):
        return None
    value = env.get(ENV, "").strip()
    if not value:
        return usable_cores()
    try:
        n = int(value)
    except ValueError:
        n = 0
    if n < 1:
        raise DeviceCountError(
            f"{ENV}={value!r}: expected a positive integer (1 turns batch sharding off)"
        )
    return n


def enable(environ: Mapping[str, str] | None = None) -> int:
    """Make :func:`resolve`'s number of JAX CPU devices; call before any JAX computation.

    Returns:
        The number of devices JAX's default backend now has. Where JAX had already started,
        nothing changes (a later setting could not take effect) and its count is returned.
    """
    n = resolve(environ)
    import jax

    if n is not None:
        # Once the backends are up the count is fixed: keep what they have.
        with contextlib.suppress(RuntimeError):
            jax.config.update("jax_num_cpu_devices", n)
    return jax.local_device_count()
