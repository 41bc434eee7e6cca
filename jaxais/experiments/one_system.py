"""n STL trials of one system in one world: the call behind ``scripts/trials.py``. Arguments
are checked before JAX starts; the same arguments give the same document, byte for byte."""

from __future__ import annotations

import os
import sys
from collections.abc import Mapping
from typing import Any

from jaxais.experiments import protocol
from jaxais.experiments.contenders import check_label, check_specs
from jaxais.io import RUN_BYTES, atomic_write_json, check_memory, check_output_file
from jaxais.labels import RANDOM_SETS, SYSTEMS
from jaxais.labels import label as label_of

__all__ = ["check_trials", "command_line", "trials"]


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


def _is_contender(system: Any) -> bool:
    """Is ``system`` a contender (a spec, a (controller, params) tuple, a Contender), not one
    of the paper's systems?"""
    return not isinstance(system, str) or ":" in system


def check_trials(
    system: Any,
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
    label: str | None = None,
    world_scale: float = 1.0,
) -> tuple[str | os.PathLike[str], int, float, int]:
    """Check :func:`trials`'s arguments without loading JAX (one-line ``ValueError``\\ s naming
    the script's flags; a contender's spec by form, label and file); returns the world, the trial
    count and the two caps, defaults filled in."""
    world = protocol.WORLDS[0] if world is None else world
    n = protocol.SIMULATED_TRIALS if trials is None else trials
    if _is_contender(system):
        if isinstance(system, str):
            check_specs([system])
        if label is not None:
            check_label(label, "label")
        if random_set or seeds:
            raise ValueError("--random-set and --seeds apply to the paper's systems, not to a "
                             "contender")  # fmt: skip
    elif system not in SYSTEMS:
        raise ValueError(
            f"unknown system {system!r} (one of {', '.join(SYSTEMS)}, or a contender: "
            "FILE.py:NAME or (controller, params))"
        )
    elif label is not None:
        raise ValueError("label names a contender; a paper system keeps its label")
    protocol.check_seed(seed)
    protocol.check_world_scale(world_scale, [str(world)])
    tau_cap, collision_cap = protocol.check_caps(tau_cap, collision_cap)
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
    return world, n, tau_cap, collision_cap


def trials(
    system: Any,
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
    label: str | None = None,
    world_scale: float = 1.0,
) -> dict[str, Any] | None:
    """Run ``trials`` STL trials of ``system`` in ``world`` (a name or ``.toml``) and return the
    results document (``config``, one record per trial, ``summary``), written to ``out`` if given;
    None on processes other than 0 of a multi-process run.

    ``system`` is a paper system (``"SIE"``; UIE and URL with ``random_set``) or a contender
    (:mod:`jaxais.experiments.contenders`): a spec ``[LABEL=]FILE.py:NAME``, a ``(controller,
    params)`` tuple or a ``Contender``; ``label`` names a tuple's trials (default
    ``contender``). ``plot`` also draws every trajectory to a PNG (the trials then run as one
    batch); ``command`` is recorded (default: the ``trials.py`` line these arguments stand for).
    ``world_scale`` scales the world and the camera's range (:func:`records.scaled_world`; not
    the real pen). Defaults are the paper's.
    """
    contender = _is_contender(system)
    if command is None:
        spec = system if isinstance(system, str) else None
        flags = {"--system": None if contender else system, "--contender": spec if contender
                 else None, "--world": world, "--trials": trials, "--seed": seed or None,
                 "--random-set": random_set, "--seeds": seeds, "--tau-cap": tau_cap,
                 "--collision-cap": collision_cap, "--out": out, "--plot": plot,
                 "--world-scale": None if world_scale == 1 else world_scale}  # fmt: skip
        command = command_line("trials.py", flags)
    world, n, tau_cap, collision_cap = check_trials(
        system, out, world=world, trials=trials, seed=seed, random_set=random_set, seeds=seeds,
        tau_cap=tau_cap, collision_cap=collision_cap, plot=plot, label=label,
        world_scale=world_scale)  # fmt: skip
    # Imported after the arguments are checked: a bad one answers at once, without loading JAX.
    import jax
    from tqdm import tqdm

    from jaxais.experiments.contenders import contender_config, one
    from jaxais.experiments.records import (
        build_systems,
        results_document,
        run_config,
        scaled_world,
    )
    from jaxais.immune.network import NetworkParams
    from jaxais.loop import EpisodeConfig
    from jaxais.trials import run_trials

    lead = jax.process_index() == 0  # every process runs its share; process 0 writes
    loaded, params = scaled_world(world, world_scale)
    config = EpisodeConfig(tau_cap=tau_cap, collision_cap=collision_cap, record=bool(plot))
    network = NetworkParams()
    if contender:  # read before any run: a bad spec fails first
        c = one(system, label)
        name, systems, controller, seed_info = c.label, {c.label: c.params}, c.controller, None
    else:
        name, controller = label_of(system, random_set or "R1"), None
        systems, seed_info = build_systems([name], seeds, network)
    total, unit = (config.max_iterations(params.dt), "it") if plot else (n, "run")
    with tqdm(total=total, desc=f"{name} in {loaded.name}", unit=unit, file=sys.stderr,
              disable=not (lead and progress)) as bar:  # fmt: skip
        results = run_trials(loaded, systems, n, seed, config, params, bar, controller=controller)
        bar.update(bar.total - bar.n)
    cfg = run_config(loaded, str(world), config, network, params, seed_info, world_scale)
    if contender:
        cfg = contender_config(cfg, c.source)
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
