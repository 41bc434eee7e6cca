"""Baselines beside the paper's systems [ours]: :mod:`jaxais.baselines.neural`, an MLP trained
by OpenES and run under the task loop (:data:`NEURAL`; :mod:`jaxais.experiments.baseline` trains
and runs it). :class:`TrainConfig` is JAX-free; the other names load on first use.
"""

from __future__ import annotations

import importlib
from typing import Any

from jaxais.baselines.config import TrainConfig

_NEURAL = ("MLPParams", "NEURAL", "TrainResult", "load_params", "make_train", "save_params")
__all__ = ["TrainConfig", "neural_controller", *_NEURAL]


def __getattr__(name: str) -> Any:
    if name in __all__:  # all but TrainConfig, imported above
        return getattr(importlib.import_module("jaxais.baselines.neural"), name)
    raise AttributeError(f"module 'jaxais.baselines' has no attribute {name!r}")
