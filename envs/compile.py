"""Compiler options for the simulator's programs.

On XLA's CPU backend (jax >= 0.7) small reductions are handed to YNNPACK by default; for the
tiny per-robot reductions of a ray caster (over 4-16 surfaces) that runs 2-3x slower than XLA's
own loops. ``jit`` below compiles with that fusion off on CPU and leaves other backends alone.
Two more option sets suit programs of a known shape: ``quick_compile`` for programs whose run
time does not matter, ``small_kernels`` for loops of many small kernels (the batched task loop).
The options are passed per program, so they never change how a user's own code compiles.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any

import jax
import numpy as np

CPU_COMPILER_OPTIONS = {"xla_cpu_experimental_ynn_fusion_type": ""}


def _accepted(options: dict[str, Any]) -> bool:
    """Whether this XLA compiles with ``options`` (an XLA without a flag rejects it)."""
    try:
        jax.jit(lambda x: x + 1, compiler_options=options)(np.zeros((), np.float32))
    except Exception:  # noqa: BLE001 (any rejection means: not these options)
        return False
    return True


@functools.cache
def _every_option_accepted() -> bool:
    """Whether this XLA takes every CPU option here: one probe compile (about 60 ms) at a
    script's start where it does, instead of one per option set."""
    options = {**CPU_COMPILER_OPTIONS, **QUICK_COMPILE_OPTIONS, **LOOP_EMITTER_OPTIONS}
    return jax.default_backend() == "cpu" and _accepted(options)


@functools.cache
def compiler_options() -> dict[str, Any] | None:
    """Options for the default backend (None where none apply or this XLA lacks them)."""
    if jax.default_backend() != "cpu":
        return None
    if _every_option_accepted() or _accepted(CPU_COMPILER_OPTIONS):
        return CPU_COMPILER_OPTIONS
    return None


LOOP_EMITTER_OPTIONS = {"xla_cpu_use_fusion_emitters": False}
"""Extra CPU options for a loop of many small kernels (``small_kernels``): XLA's older loop
emitters instead of its fusion emitters, which compile each kernel faster and fuse a little more.
Measured on a 2-core CPU, against the fusion emitters:

- the task loop of 30 SIE trials in world1 (15 runs per device): 111 -> 98 kernels, 5.8 -> 4.3 s
  of CPU to compile, the same time per iteration; ``trials.py`` 9.9-11.7 -> 9.0-10.8 s of wall
  time (five interleaved pairs), 12.3-14.5 -> 12.4-13.6 s (four pairs on a busier machine);
- ``reproduce.py`` (105 runs per device): compilation 26-27 -> 22 s, the loops about 5 % slower,
  99-102 -> 100 s in all (two pairs); ``evolve.py`` 22.2-24.3 -> 21.7-23.6 s (three pairs);
- the GA gives the same seed bit for bit. The STL loop rounds a rare step differently in the
  last bit, after which that trial's chaotic run drifts apart: world1's 30 SIE trials kept their
  τ, c and f (one idiotypic difference rate moved), other systems' and worlds' means moved a
  little;
- not for large arrays: the bare simulator at batch 10,000 ran about a third slower in one
  benchmark."""

QUICK_COMPILE_OPTIONS = {"xla_backend_optimization_level": 1, **LOOP_EMITTER_OPTIONS}
"""Extra CPU options for a program whose run time does not matter (a reset, which runs once per
batch; a GA breeding step). LLVM's cheaper pipeline (-O1) compiles it about a third faster
(world1's batched reset: 1.6 s instead of 2.3 s on a 2-core CPU), and XLA's older loop emitters
(:data:`LOOP_EMITTER_OPTIONS`) take another third off (the STL's batched reset for 30 trials:
4.3-4.9 -> 2.7-2.8 s of CPU in world1 and world2, 6.5 -> 3.7 s in ``real``). Neither involves
fast-math, and the numbers are unchanged (checked bit for bit: the reset in all three STL worlds,
the shipped LTL seed, world1's SIE trials). Not for the task loop itself: at -O1 it runs up to
2x slower."""


def _extended(*extras: dict[str, Any]) -> dict[str, Any] | None:
    """:func:`compiler_options` plus the first of ``extras`` this XLA accepts (none: as is)."""
    options = compiler_options()
    if options is None:
        return None
    for extra in extras:
        candidate = {**options, **extra}
        if _every_option_accepted() or _accepted(candidate):
            return candidate
    return options


@functools.cache
def quick_compile_options() -> dict[str, Any] | None:
    """:func:`compiler_options` plus those of :data:`QUICK_COMPILE_OPTIONS` this XLA accepts."""
    return _extended(QUICK_COMPILE_OPTIONS, {"xla_backend_optimization_level": 1})


@functools.cache
def small_kernel_options() -> dict[str, Any] | None:
    """:func:`compiler_options` plus :data:`LOOP_EMITTER_OPTIONS` where this XLA accepts them."""
    return _extended(LOOP_EMITTER_OPTIONS)


class _Jit:
    """``jax.jit(fun, compiler_options=..., **kwargs)``, made on first use.

    Building it lazily keeps a module-level ``@jit`` from starting JAX's backends at import
    time, so a script can still choose its devices (``jaxais.host_devices``) after imports.
    """

    def __init__(self, fun: Callable[..., Any], options: Callable[[], Any], kwargs: dict[str, Any]):
        functools.update_wrapper(self, fun)
        self._fun, self._options, self._kwargs = fun, options, kwargs

    @functools.cached_property
    def _jitted(self) -> Any:
        return jax.jit(self._fun, compiler_options=self._options(), **self._kwargs)

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        return self._jitted(*args, **kwargs)

    def __getattr__(self, name: str) -> Any:  # lower, trace, eval_shape, ...
        return getattr(self._jitted, name)


def jit(
    fun: Callable[..., Any],
    quick_compile: bool = False,
    small_kernels: bool = False,
    **kwargs: Any,
) -> Callable[..., Any]:
    """``jax.jit`` with :func:`compiler_options` for the default backend (resolved on first use).

    Args:
        quick_compile: the program's run time does not matter (it runs once per batch, or does
            little work): compile it for compile speed (:data:`QUICK_COMPILE_OPTIONS` on CPU).
        small_kernels: the program is a loop of many small kernels, such as the task loop at
            tens to hundreds of robots per device (:data:`LOOP_EMITTER_OPTIONS` on CPU).
    """
    if quick_compile and small_kernels:
        raise ValueError("choose one of quick_compile and small_kernels")
    if quick_compile:
        return _Jit(fun, quick_compile_options, kwargs)
    return _Jit(fun, small_kernel_options if small_kernels else compiler_options, kwargs)
