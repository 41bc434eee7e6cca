"""Console entry points (``jaxais-evolve``, ``jaxais-trials``, ``jaxais-reproduce``).

The scripts live in the checkout's ``scripts/`` folder, which is not a package and is not
installed; each entry point runs its script exactly as ``python scripts/NAME.py ARGS`` would
(as ``__main__``, with the scripts folder first on ``sys.path``), so the script's flags, errors
and exit status are the same. That needs a source checkout installed with ``pip install -e .``;
elsewhere the entry point says so in one line and exits with status 2.

This module imports neither JAX nor the rest of jaxais: the script decides when JAX starts.
"""

from __future__ import annotations

import runpy
import sys
from pathlib import Path
from typing import NoReturn

SCRIPTS_DIR = Path(__file__).resolve().parent.parent / "scripts"
"""Where the scripts are: ``scripts/`` beside the ``jaxais`` package in a checkout."""


def run(name: str) -> NoReturn:
    """Run ``scripts/{name}.py`` as the main program, with this process's arguments."""
    path = SCRIPTS_DIR / f"{name}.py"
    if not path.is_file():
        sys.stderr.write(
            f"jaxais-{name}: error: {path} not found; the console scripts run the scripts of a "
            "source checkout: install one with pip install -e .\n"
        )
        raise SystemExit(2)
    sys.argv[0] = str(path)
    sys.path.insert(0, str(SCRIPTS_DIR))
    # The script ends the process itself (jaxais.cli.run_script); SystemExit passes through.
    runpy.run_path(str(path), run_name="__main__")
    raise SystemExit(0)


def evolve() -> NoReturn:
    """``jaxais-evolve``: ``scripts/evolve.py`` (the LTL genetic algorithm)."""
    run("evolve")


def trials() -> NoReturn:
    """``jaxais-trials``: ``scripts/trials.py`` (n STL trials of one system in one world)."""
    run("trials")


def reproduce() -> NoReturn:
    """``jaxais-reproduce``: ``scripts/reproduce.py`` (the paper's experiments)."""
    run("reproduce")
