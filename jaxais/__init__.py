"""jaxais: evolve and run idiotypic immune-network controllers for e-puck robots, in JAX."""

from __future__ import annotations

from pathlib import Path

__version__ = "0.1.0"

# In a source checkout the simulator lives in ../envs (installed as jaxais.envs by pip); make
# ``import jaxais.envs`` work there too, e.g. for ``python -c`` run from the repository root.
_checkout_envs = Path(__file__).resolve().parent.parent / "envs"
if (_checkout_envs / "worlds").is_dir() and not (Path(__file__).parent / "envs").is_dir():
    __path__.append(str(_checkout_envs.parent))  # noqa: F821 (module __path__)
