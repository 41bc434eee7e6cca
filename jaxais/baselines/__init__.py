"""Baselines beside the paper's systems [ours].

:mod:`jaxais.baselines.neural`: a small neural controller (an MLP from the IR and camera
features to the wheel speeds) trained by OpenES on the gymnax-style environment, and run under
the task loop like SIE and HDC (:data:`NEURAL`); :mod:`jaxais.experiments.baseline` trains it
and runs it beside them (an experiment: it sits on top). Its settings,
:class:`~jaxais.baselines.config.TrainConfig`, live in a module free of JAX, so a script checks
its flags before JAX starts; the other names load on first use.
"""

from __future__ import annotations

import importlib
from typing import Any

from jaxais.baselines.config import TrainConfig

_EXPORTS = {
    **dict.fromkeys(
        (
            "MLPParams",
            "NEURAL",
            "TrainResult",
            "load_params",
            "make_train",
            "neural_controller",
            "save_params",
        ),
        "neural",
    ),  # fmt: skip
}
__all__ = ["TrainConfig", *_EXPORTS]


def __getattr__(name: str) -> Any:
    if name in _EXPORTS:
        return getattr(importlib.import_module(f"jaxais.baselines.{_EXPORTS[name]}"), name)
    raise AttributeError(f"module 'jaxais.baselines' has no attribute {name!r}")
