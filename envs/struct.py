"""Frozen dataclasses registered as JAX pytrees (the state and parameter containers)."""

from __future__ import annotations

import dataclasses
import typing
from typing import Any

import jax
import numpy as np


def static_field(**kwargs: Any) -> Any:
    """A dataclass field kept out of the pytree leaves (shapes, names, flags fixed when traced)."""
    return dataclasses.field(metadata={"static": True}, **kwargs)


def device_array(x: Any, dtype: Any = None) -> jax.Array:
    """``x`` converted by NumPy, then put on the default device: ``jnp.asarray`` compiles once
    per shape and dtype, about twenty times at a script's start (docs/performance.md)."""
    return jax.device_put(np.asarray(x, dtype))


def pytree_dataclass(cls: type) -> type:
    """``cls`` as a frozen dataclass pytree with ``replace``; :func:`static_field` fields
    are metadata (part of the compiled function's identity), the others leaves."""
    cls = dataclasses.dataclass(frozen=True)(cls)
    fields = dataclasses.fields(cls)
    meta = [f.name for f in fields if f.metadata.get("static", False)]
    data = [f.name for f in fields if not f.metadata.get("static", False)]
    jax.tree_util.register_dataclass(cls, data_fields=data, meta_fields=meta)
    cls.replace = lambda self, **kw: dataclasses.replace(self, **kw)
    return cls


class ArgumentTypeError(ValueError, TypeError):
    """An argument of the wrong type (one line): a ValueError and a TypeError, as
    ``jaxais.io.ArgumentTypeError`` is (envs imports nothing from jaxais, hence its own)."""


def check_type(value: Any, kind: Any, name: str, what: str) -> None:
    """:class:`ArgumentTypeError` "``name`` must be ``what``, got <type> <value>" unless ``value``
    is a ``kind``; a bool is no number unless ``kind`` is bool (``jaxais.io.check_type``'s rule)."""
    ok = isinstance(value, kind)
    if ok and isinstance(value, bool | np.bool_):
        kinds = typing.get_args(kind) or (kind if isinstance(kind, tuple) else (kind,))
        ok = any(k in (bool, np.bool_, object) for k in kinds)
    if not ok:
        got = type(value).__name__
        if isinstance(value, str | int | float):
            got += f" {value!r:.40}"
        raise ArgumentTypeError(f"{name} must be {what}, got {got}")
