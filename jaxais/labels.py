"""The systems' names: codes, random sets and table labels, and the worlds' names by way of
:func:`world_names_module` (JAX-free: scripts check flags)."""

from __future__ import annotations

import importlib
import importlib.util
import sys
from pathlib import Path
from types import ModuleType

from jaxais.io import load_module_file

__all__ = ["LABELS", "RANDOM_SETS", "SYSTEMS", "label", "parse_label", "world_names_module"]

SYSTEMS = ("SIE", "SRL", "UIE", "URL", "HDC")  # SPEC 8
RANDOM_SETS = {"R1": 1, "R2": 2}  # the fixed random initial sets: their PRNG seeds [ours]
# The paper's table order (a label's random stream comes from its name, not its place).
LABELS = ("SIE", "SRL", "UIE-R1", "URL-R1", "UIE-R2", "URL-R2", "HDC")


def label(system: str, random_set: str | None = None) -> str:
    """Table label of a system: ``UIE`` with R1 is ``UIE-R1``; seeded systems and HDC as is."""
    return f"{system}-{random_set}" if system in ("UIE", "URL") else system


def parse_label(name: str) -> tuple[str, str | None]:
    """Inverse of :func:`label`: ``"URL-R2"`` -> ``("URL", "R2")``."""
    system, _, random_set = name.partition("-")
    if system not in SYSTEMS or (system in ("UIE", "URL")) != bool(random_set):
        raise ValueError(f"unknown system {name!r} (one of {', '.join(LABELS)})")
    if random_set and random_set not in RANDOM_SETS:
        raise ValueError(f"unknown random set {random_set!r} (one of {', '.join(RANDOM_SETS)})")
    return system, random_set or None


_NAMES = "jaxais.envs.names"


def world_names_module() -> ModuleType:
    """``jaxais.envs.names`` (the world lookup: built-ins and ``JAXAIS_WORLDS``) without JAX:
    loaded by its file, as importing it the usual way runs ``jaxais.envs``'s ``__init__``, which
    imports JAX. Registered under its own name, so ``jaxais.envs`` imported later uses it too
    (one ``WorldError``)."""
    if _NAMES in sys.modules or "jaxais.envs" in sys.modules:
        return importlib.import_module(_NAMES)
    spec = importlib.util.find_spec("jaxais.envs")
    file = Path(spec.origin).with_name("names.py") if spec and spec.origin else None
    if file is None or not file.is_file():  # an install without plain files: JAX it is
        return importlib.import_module(_NAMES)
    return load_module_file(_NAMES, file)
