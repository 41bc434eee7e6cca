"""Contenders: controllers beyond the paper's, run under its protocol beside its systems.

A contender is ``(controller, params)``: any :class:`jaxais.controllers.Controller` and its
parameter pytree (what ``run_trials(..., controller=controller)`` runs). It is given from Python
as that tuple, or by a spec naming one in a user's file or module:

- ``FILE.py:NAME`` or ``package.module:NAME``, optionally ``LABEL=`` in front (the label
  defaults to ``NAME``); ``NAME`` is the tuple or a function of no arguments returning it.

A label is an identifier that is not one of the paper's labels; it names the contender's random
streams, its trials files and its rows. Each contender runs in a pool of its own (never in a
batch with the paper's systems), so the paper's records do not depend on what runs beside them.
The neural baseline is the contender ``NN`` (:func:`neural`).
"""

from __future__ import annotations

import hashlib
import importlib
import os
import sys
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from jaxais.baselines.config import NN_LABEL
from jaxais.io import ArgumentTypeError, UserError, load_module_file
from jaxais.labels import LABELS, SYSTEMS

__all__ = [
    "Contender",
    "add_argument",
    "check_label",
    "check_specs",
    "contender_config",
    "load_spec",
    "neural",
    "one",
    "resolve",
    "spec_file",
    "spec_sha256",
]

_RESERVED = {*LABELS, *SYSTEMS, "SIE_hold1"}  # the paper's labels and the calibration file's


@dataclass(frozen=True)
class Contender:
    """One contender: its ``label``, ``controller`` and ``params`` (a pytree), and ``source``,
    the JSON a run records to regenerate it (``spec`` and the file's ``sha256``; ``spec`` None
    for an object given from Python)."""

    label: str
    controller: Any
    params: Any
    source: dict[str, Any] = field(default_factory=dict)


def add_argument(parser: Any, repeatable: bool = True, group: Any = None) -> None:
    """Add ``--contender SPEC`` to a script's flags (``group``: a mutually exclusive group)."""
    text = (
        "a controller beyond the paper's: [LABEL=]FILE.py:NAME or [LABEL=]package.module:NAME, "
        "NAME a (Controller, params) tuple or a function returning one (docs/extending.md)"
    )
    (group or parser).add_argument(
        "--contender",
        action="append" if repeatable else "store",
        default=None,
        metavar="SPEC",
        help=text + ("; repeatable" if repeatable else ""),
    )


def check_label(label: Any, flag: str = "--contender") -> str:
    """``label`` if it is an identifier that is not one of the paper's labels (one-line error)."""
    if not isinstance(label, str):
        raise ArgumentTypeError(f"{flag}: a label must be a string, got {type(label).__name__}")
    if not label.isidentifier():
        raise UserError(f"{flag}: label {label!r} must be an identifier (letters, digits, _)")
    if label in _RESERVED:
        raise UserError(f"{flag}: label {label!r} is the paper's; name the contender otherwise")
    return label


def _split(spec: str) -> tuple[str | None, str, str]:
    """``[LABEL=]TARGET:NAME`` -> (label or None, target, name); one-line error otherwise."""
    label, sep, rest = spec.partition("=")
    if not sep:
        label, rest = None, spec
    target, colon, name = rest.rpartition(":")
    if not colon or not target or not name.isidentifier():
        raise UserError(
            f"--contender {spec!r}: write [LABEL=]FILE.py:NAME or [LABEL=]package.module:NAME"
        )
    return label, target, name


def check_specs(specs: Any) -> list[tuple[str, str]]:
    """(label, spec) of each ``--contender`` spec, checked without running it: the form, the
    label, a file that exists; each label once. JAX-free (scripts call it before JAX starts)."""
    if specs is None:
        return []
    if isinstance(specs, str):
        specs = [specs]
    out = []
    for spec in specs:
        if not isinstance(spec, str):
            raise ArgumentTypeError(f"--contender must be a spec string, got {spec!r:.40}")
        label, target, name = _split(spec)
        label = check_label(name if label is None else label)
        if target.endswith(".py") and not Path(target).is_file():
            raise UserError(f"--contender {spec!r}: no such file {target}")
        out.append((label, spec))
    labels = [label for label, _ in out]
    if len(set(labels)) < len(labels):
        raise UserError(f"--contender: label given twice in {', '.join(labels)}")
    return out


def spec_file(spec: str) -> Path | None:
    """The file a ``FILE.py:NAME`` spec names (None for a module's spec)."""
    _, target, _ = _split(spec)
    return Path(target) if target.endswith(".py") else None


def spec_sha256(spec: str) -> str | None:
    """The sha256 of the file a ``FILE.py:NAME`` spec names (None for a module's spec)."""
    path = spec_file(spec)
    return None if path is None else _sha256(path)


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _module(target: str, spec: str):
    """The module a spec names: a ``.py`` file executed as a fresh module, or an import."""
    try:
        if target.endswith(".py"):
            path = Path(target)
            if not path.is_file():
                raise UserError(f"--contender {spec!r}: no such file {target}")
            name = f"_jaxais_contender_{_sha256(path)[:16]}"
            if name in sys.modules:  # the same file twice: one module, one controller
                return sys.modules[name], path
            return load_module_file(name, path), path
        module = importlib.import_module(target)
        file = getattr(module, "__file__", None)
        return module, Path(file) if file else None
    except UserError:
        raise
    except Exception as err:  # the user's code failed: its message, in one line
        message = " ".join(f"{type(err).__name__}: {err}".split())
        raise UserError(f"--contender {spec!r}: cannot load {target}: {message[:300]}") from None


def _as_pair(obj: Any, spec: str) -> tuple[Any, Any]:
    """``obj`` (or what it returns, if a function) as (controller, params); one line otherwise."""
    from jaxais.controllers import Controller

    if callable(obj) and not isinstance(obj, tuple):
        try:
            obj = obj()
        except Exception as err:
            message = " ".join(f"{type(err).__name__}: {err}".split())
            raise UserError(f"--contender {spec!r}: calling it failed: {message[:300]}") from None
    if not (isinstance(obj, tuple | list) and len(obj) == 2 and isinstance(obj[0], Controller)):
        got = type(obj).__name__
        raise UserError(
            f"--contender {spec!r}: NAME must be a (Controller, params) tuple or a function of "
            f"no arguments returning one, got {got}"
        )
    return obj[0], obj[1]


def load_spec(spec: str) -> Contender:
    """The contender a spec names (module docstring), with its source recorded."""
    ((label, _),) = check_specs([spec])
    _, target, name = _split(spec)
    module, path = _module(target, spec)
    if not hasattr(module, name):
        raise UserError(f"--contender {spec!r}: {target} defines no {name!r}")
    obj = getattr(module, name)
    controller, params = _as_pair(obj, spec)
    if target.endswith(".py"):  # no record names a machine's directories
        from jaxais.experiments.records import portable_path

        spec = spec.replace(f"{target}:", f"{portable_path(target)}:")
    source: dict[str, Any] = {"spec": spec}
    doc = (obj.__doc__ if callable(obj) else None) or module.__doc__
    if doc and doc.strip():  # its first sentence describes it in the report
        source["about"] = " ".join(doc.strip().split("\n\n")[0].split())
    if path is not None and path.is_file():
        source["sha256"] = _sha256(path)
    return Contender(label, controller, params, source)


def neural(directory: str | os.PathLike[str] | None = None) -> Contender:
    """The neural baseline as the contender ``NN``: trained weights (default: the shipped
    ``checkpoints/neural``) and what made them."""
    from jaxais.baselines.neural import NEURAL, load_params

    params, info = load_params(directory)
    made_by = {"config": info.get("config"), "seed": info.get("seed")}
    where = "shipped (checkpoints/neural)" if directory is None else str(directory)
    trained = made_by["config"] or {}
    about = (
        "A small neural controller (an MLP from the IR and camera features to the wheel "
        "speeds), trained by an evolution strategy"
        + (f" in {trained['world']}" if "world" in trained else "")
        + " (`scripts/train_baseline.py`, `docs/baseline.md`)."
    )
    source = {"weights": where, "made_by": made_by, "about": about}
    return Contender(NN_LABEL, NEURAL, params, source)


def one(contender: Any, label: str | None = None) -> Contender:
    """One contender as :func:`resolve` reads it: a spec or a :class:`Contender` keeps its own
    label unless ``label`` is given; a ``(controller, params)`` tuple takes ``label`` (default
    ``contender``)."""
    if label is None and isinstance(contender, str | Contender):
        return resolve([contender])[0]
    return resolve({label or "contender": contender})[0]


def contender_config(config: Mapping[str, Any], source: Mapping[str, Any]) -> dict[str, Any]:
    """A run's config (:func:`jaxais.experiments.records.run_config`) for a contender's trials:
    the network's parts and the LTL seed do not apply; how the contender was given does."""
    kept = {k: v for k, v in config.items() if k not in ("network", "readings", "ltl_seed")}
    return kept | {"contender": dict(source)}


def resolve(contenders: Any) -> list[Contender]:
    """``contenders`` as a list: a mapping label -> ``(controller, params)``, a spec or a
    :class:`Contender`; or a sequence of specs or Contenders. Every spec is loaded and every
    label checked (one-line errors) before anything runs."""
    if contenders is None:
        return []
    if isinstance(contenders, str | Contender):
        contenders = [contenders]
    items: list[Contender] = []
    if isinstance(contenders, Mapping):
        for label, value in contenders.items():
            check_label(label, "contenders")
            if isinstance(value, str):
                loaded = load_spec(value)
                items.append(Contender(label, loaded.controller, loaded.params, loaded.source))
            elif isinstance(value, Contender):
                items.append(Contender(label, value.controller, value.params, value.source))
            else:
                controller, params = _as_pair(value, f"contenders[{label!r}]")
                items.append(Contender(label, controller, params, {"spec": None}))
    else:
        if not isinstance(contenders, list | tuple):
            raise ArgumentTypeError(
                "contenders must be a dict label -> (controller, params) or spec, or a list of "
                f"specs, got {type(contenders).__name__}"
            )
        for value in contenders:
            if isinstance(value, Contender):
                check_label(value.label, "contenders")
                items.append(value)
            else:
                items.append(load_spec(value))
    labels = [c.label for c in items]
    if len(set(labels)) < len(labels):
        raise UserError(f"contenders: a label given twice in {', '.join(labels)}")
    return items
