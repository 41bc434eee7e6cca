"""Small while loops compiled as one kernel each, for the GA's script (XLA's CPU setting).

XLA's CPU runtime runs a program as a sequence of kernels, one per fused operation, and inside
a ``while_loop`` it dispatches them one by one on every iteration. The GA's task loop is a body
of about 50 small kernels for 25 robots per device, so that dispatch is a good part of each
iteration. XLA can instead compile a while loop whose one iteration reads and writes fewer than
a threshold of bytes into a single function (its ``SmallWhileLoopHoistingPass``; the default
threshold is 1 KiB). :func:`enable` raises the threshold to :data:`DEFAULT_BYTES`, which covers
the GA's chunk loop and its driver loop at the default 50 robots (about 0.16 MB and 0.25 MB at
25 robots per device), up to 50 robots per device.

Measured on a 2-core CPU (separate processes, interleaved): a generation's evaluation 0.58-0.64 s
-> 0.47-0.53 s; ``scripts/evolve.py``, five pairs: 32.0-35.5 s -> 27.6-31.7 s wall; the same seed
bit for bit (checked against ``checkpoints/default``).

Only ``scripts/evolve.py`` uses it, for two reasons measured on the STL's task loop:

- the one-function form rounds some rare step differently in the last bit (probably multiply-adds
  that LLVM now contracts across what were separate kernels): 3 of world1's 30 SIE trials drift
  apart after a few thousand iterations. Whether a loop qualifies depends on the batch per
  device, so ``trials.py`` (15 runs per device) would disagree with ``reproduce.py`` (75 and
  more, above the threshold) and with a one-device run;
- XLA compiles a one-function loop on one thread. For 30 SIE trials the run drops from 6.7-8.5 s
  to 5.6-6.0 s but the compile grows by 1-2 s; with every loop of ``reproduce.py`` hoisted
  (threshold 1 GB) its compile went from 40 s to 70 s for a run 96 s -> 88 s (154 s -> 175 s).

XLA reads the setting from ``XLA_FLAGS`` once per process, when its CPU backend starts; it
cannot be set per program. First match wins:

1. ``--xla_backend_extra_options`` already in ``XLA_FLAGS``: the user's options, left alone;
2. ``JAXAIS_LOOP_KERNEL_BYTES``: a byte threshold (``0`` or ``off``: leave XLA's default);
3. :data:`DEFAULT_BYTES`.
"""

from __future__ import annotations

import os
from collections.abc import MutableMapping

ENV = "JAXAIS_LOOP_KERNEL_BYTES"
"""Environment variable: the threshold in bytes (``0`` or ``off``: XLA's default)."""
DEFAULT_BYTES = 512 * 1024
"""Loops whose one iteration touches fewer bytes than this become one kernel."""
_OPTION = "--xla_backend_extra_options"
_NAME = "xla_cpu_small_while_loop_byte_threshold"


class LoopKernelError(ValueError):
    """``JAXAIS_LOOP_KERNEL_BYTES`` is not a byte count (the message is one line)."""


def resolve(environ: MutableMapping[str, str] | None = None) -> int | None:
    """The threshold :func:`enable` would set, or None where it leaves ``XLA_FLAGS`` alone.

    Raises:
        LoopKernelError: ``JAXAIS_LOOP_KERNEL_BYTES`` is neither a non-negative integer nor off.
    """
    env = os.environ if environ is None else environ
    if _OPTION in env.get("XLA_FLAGS", ""):
        return None
    value = env.get(ENV, "").strip()
    if not value:
        return DEFAULT_BYTES
    if value.lower() == "off":
        return None
    try:
        n = int(value)
    except ValueError:
        n = -1
    if n < 0:
        raise LoopKernelError(
            f"{ENV}={value!r}: expected a byte count (an integer >= 0; 0 or off keeps XLA's"
            " default)"
        )
    return n or None


def _backends_started() -> bool:
    """Whether JAX's backends are up (XLA has then read its flags); False if JAX cannot say."""
    try:
        from jax._src import xla_bridge

        return bool(xla_bridge.backends_are_initialized())
    except (ImportError, AttributeError):  # another jax: assume not, setting XLA_FLAGS is harmless
        return False


def enable(environ: MutableMapping[str, str] | None = None) -> int | None:
    """Add :func:`resolve`'s threshold to ``XLA_FLAGS``; call before the first JAX computation.

    Returns:
        The threshold set, or None where nothing was changed: :func:`resolve` said so, or
        JAX's backends had already started, so the flag could no longer take effect.
    """
    env = os.environ if environ is None else environ
    n = resolve(env)
    if n is None or _backends_started():
        return None
    env["XLA_FLAGS"] = " ".join([*env.get("XLA_FLAGS", "").split(), f"{_OPTION}={_NAME}={n}"])
    return n
