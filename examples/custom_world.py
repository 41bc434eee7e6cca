"""A world of your own: one TOML file, no edit to jaxais.

    python examples/custom_world.py          # 30 SIE trials in examples/worlds/corridor.toml
    python examples/custom_world.py --tiny   # 4 short trials (the tests run this)

A world is one file: ``examples/worlds/corridor.toml`` here (the format, every field and range,
is described in jaxais's ``envs/worlds/world1.toml``). Load it by its path, or put its folder on
the search path ``JAXAIS_WORLDS`` (folders separated by ``os.pathsep``, as ``PATH``) and load it
by name, as a built-in world is: ``envs.load_world("corridor")``, ``envs.make("corridor")``,
``TrialsConfig(world="corridor")``, ``--world corridor`` in the scripts. Found by name, a world's
``name`` field must be its file's name, and a built-in world's name (``ga_maze``, ``world1``, ...)
cannot be taken: ``envs.world_names()`` lists every name.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import numpy as np

WORLDS = Path(__file__).resolve().parent / "worlds"  # the user's world folder


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tiny", action="store_true", help="4 trials of at most 30 s")
    args = parser.parse_args(argv)

    # The search path, as a shell would set it: export JAXAIS_WORLDS=examples/worlds
    os.environ["JAXAIS_WORLDS"] = os.pathsep.join(
        [str(WORLDS), *filter(None, [os.environ.get("JAXAIS_WORLDS")])]
    )
    from jaxais import EpisodeConfig, envs, load_seed, make_system, run_trials

    by_path = envs.load_world(WORLDS / "corridor.toml")
    world = envs.load_world("corridor")  # found through JAXAIS_WORLDS
    assert world.name == by_path.name == "corridor"
    print(f"worlds by name: {', '.join(envs.world_names())}")

    trials, tau_cap = (4, 30.0) if args.tiny else (30, 500.0)
    systems = {"SIE": make_system("SIE", load_seed()[0])}
    results = run_trials(world, systems, trials, seed=0, config=EpisodeConfig(tau_cap=tau_cap))
    records = results["SIE"].records
    tau = np.mean([r["tau"] for r in records])
    collisions = np.mean([r["collisions"] for r in records])
    print(
        f"SIE in corridor: {len(records)} trials, mean tau {tau:.1f} s (cap {tau_cap:g} s), "
        f"mean collisions {collisions:.1f}"
    )


if __name__ == "__main__":
    main()
