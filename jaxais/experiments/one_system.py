"""n STL trials of one system in one world: the call behind ``scripts/trials.py``.

:func:`trials` checks its arguments before JAX starts (one-line ``ValueError``\\ s naming the
script's flags), runs the trials in a compiled, vmapped pool of slots (each refilled when its
trial ends) or, with ``plot``, as one batch that keeps every trajectory, and returns the results
document (written to ``out`` when given). The pool is sharded over every device JAX sees; in a
multi-process run (``jax.distributed``) process 0 writes. The same arguments give the same
document, byte for byte.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable, Mapping
from typing import Any

from jaxais.experiments import protocol
from jaxais.io import RUN_BYTES, atomic_write_json, check_memory, check_output_file
from jaxais.labels import RANDOM_SETS, SYSTEMS, label

__all__ = ["command_line", "trials"]


def command_line(prog: str, flags: Mapping[str, Any]) -> str:
    """The command a call stands for, for its records: ``prog`` and each flag whose value is set
    (True: the bare flag; None and False: left out; floats as ``%g``)."""
    words = [prog]
    for flag, value in flags.items():
        if value is True:
            words.append(flag)
        elif value is not None and value is not False:
            words += [flag, f"{value:g}" if isinstance(value, float) else str(value)]
    return " ".join(words)


def trials(
    system: str,
    out: str | os.PathLike[str] | None = None,
    *,
    world: str | os.PathLike[str] | None = None,
    trials: int | None = None,
    seed: int = 0,
    random_set: str | None = None,
    seeds: str | os.PathLike[str] | None = None,
    tau_cap: float | None = None,
    collision_cap: int | None = None,
    plot: str | os.PathLike[str] | None = None,
    progress: bool = True,
    command: str | None = None,
    before_jax: Callable[[], object] | None = None,
) -> dict[str, Any] | None:
    """Run ``trials`` STL trials of ``system`` in ``world`` and return their results document.

    Args:
        system: one of :data:`jaxais.labels.SYSTEMS`.
        out: the results JSON file (None: write nothing).
        world: a built-in world's name or a ``.toml`` path (default: the protocol's first).
        trials: how many (default: the paper's count in a simulated world).
        seed: the trials' PRNG seed, in [0, 2**32).
        random_set: the unseeded systems' fixed random set (default R1).
        seeds: the LTL seed directory of SIE and SRL (default: the shipped one).
        tau_cap, collision_cap: the caps (default: the paper's).
        plot: also draw every trial's trajectory to this PNG (the trials then run as one batch).
        progress: show a progress bar on stderr.
        command: the command recorded in the document (default: the ``trials.py`` command line
            these arguments stand for).
        before_jax: called once the arguments are checked, before JAX computes anything (the
            scripts' XLA and multi-process settings, :mod:`jaxais._speed`).

    Returns:
        The results document: ``system``, ``label``, ``world``, ``random_set``, ``seed``,
        ``config`` (every parameter used), ``trials`` (one record per trial), ``summary``; None
        on the other processes of a multi-process run (process 0 writes).
    """
    if command is None:
        flags = {"--system": system, "--world": world, "--trials": trials, "--seed": seed or None,
                 "--random-set": random_set, "--seeds": seeds, "--tau-cap": tau_cap,
                 "--collision-cap": collision_cap, "--out": out, "--plot": plot}  # fmt: skip
        command = command_line("trials.py", flags)
    world = protocol.WORLDS[0] if world is None else world
    n = protocol.SIMULATED_TRIALS if trials is None else trials
    tau_cap = float(protocol.TAU_CAP if tau_cap is None else tau_cap)  # 10 and 10.0: one record
    collision_cap = int(protocol.COLLISION_CAP if collision_cap is None else collision_cap)
    if system not in SYSTEMS:
        raise ValueError(f"unknown system {system!r} (one of {', '.join(SYSTEMS)})")
    if not 0 <= seed < 2**32:
        raise ValueError(f"--seed must be in [0, 2**32), got {seed}")
    if n < 1:
        raise ValueError(f"--trials must be >= 1, got {n}")
    if random_set and system not in ("UIE", "URL"):
        raise ValueError(f"--random-set applies to UIE and URL only, not {system}")
    if random_set and random_set not in RANDOM_SETS:
        raise ValueError(f"unknown random set {random_set!r} (one of {', '.join(RANDOM_SETS)})")
    if seeds and system not in ("SIE", "SRL"):
        raise ValueError(f"--seeds applies to the seeded systems SIE and SRL, not {system}")
    # A plot keeps every trajectory: a pose (3 float32) per 0.8 s, to 4000 s, held thrice.
    check_memory(n, RUN_BYTES + (180_000 if plot else 0), "--trials")
    if out is not None:
        check_output_file(out, (".json",))
    if plot:
        check_output_file(plot, (".png",))

    if before_jax is not None:
        before_jax()
    # Imported after the arguments are checked: a bad one answers at once, without loading JAX.
    import jax
    from tqdm import tqdm

    from jaxais import envs
    from jaxais.experiments.records import build_systems, results_document, run_config
    from jaxais.immune.network import NetworkParams
    from jaxais.loop import EpisodeConfig
    from jaxais.trials import run_trials

    lead = jax.process_index() == 0  # every process runs its share; process 0 writes
    name = label(system, random_set or "R1")
    loaded = envs.load_world(world)
    config = EpisodeConfig(tau_cap=tau_cap, collision_cap=collision_cap, record=bool(plot))
    network = NetworkParams()
    systems, seed_info = build_systems([name], seeds, network)
    params = envs.default_params()
    total, unit = (config.max_iterations(params.dt), "it") if plot else (n, "run")
    with tqdm(total=total, desc=f"{name} in {loaded.name}", unit=unit, file=sys.stderr,
              disable=not (lead and progress)) as bar:  # fmt: skip
        results = run_trials(loaded, systems, n, seed, config, params, bar)
        bar.update(bar.total - bar.n)
    cfg = run_config(loaded, str(world), config, network, params, seed_info)
    cfg["command"] = command
    doc = results_document(name, loaded.name, seed, results[name], cfg)
    if not lead:
        return None
    if out is not None:
        atomic_write_json(out, doc)
    if plot:
        from jaxais.experiments.plotting import save_figure, world_figure

        trajs = results[name].trajectories
        # Each trial's boxes and goal where its world placed them (outlined in its colour).
        fig = world_figure(
            loaded,
            states=results[name].placements,
            trajectories=trajs,
            title=f"{name} in {loaded.name}",
            labels=[f"trial {i}" for i in range(len(trajs))],
        )
        save_figure(fig, plot)
    return doc
