"""Compiler options for the simulator's programs.

On XLA's CPU backend (jax >= 0.7) small reductions are handed to YNNPACK by default; for the
tiny per-robot reductions of a ray caster (over 4-16 surfaces) that runs 2-3x slower than XLA's
own loops. ``jit`` below compiles with that fusion off on CPU and leaves other backends alone.
The option is passed per program, so it never changes how a user's own code compiles.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp

CPU_COMPILER_OPTIONS = {"xla_cpu_experimental_ynn_fusion_type": ""}


@functools.cache
def compiler_options() -> dict[str, str] | None:
    """Options for the default backend (None where none apply or this XLA lacks them)."""
    if jax.default_backend() != "cpu":
        return None
    try:  # an XLA without the flag rejects it: then compile with defaults
        jax.jit(lambda x: x + 1, compiler_options=CPU_COMPILER_OPTIONS)(jnp.zeros(()))
    except Exception:  # noqa: BLE001 (any rejection means: no options)
        return None
    return CPU_COMPILER_OPTIONS


def jit(fun: Callable[..., Any], **kwargs: Any) -> Callable[..., Any]:
    """``jax.jit`` with :func:`compiler_options` for the default backend."""
    return jax.jit(fun, compiler_options=compiler_options(), **kwargs)
