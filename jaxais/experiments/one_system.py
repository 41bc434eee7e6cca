"""n STL trials of one system in one world: the call behind ``scripts/trials.py``. Arguments
are checked before JAX starts; the same arguments give the same document, byte for byte."""

from __future__ import annotations

import os
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from jaxais.experiments import protocol
from jaxais.experiments.contenders import check_label, check_specs
from jaxais.io import (
    INTEGER,
    PATH,
    RUN_BYTES,
    atomic_write_json,
    check_bool,
    check_memory,
    check_output_file,
    check_path,
    check_type,
)
from jaxais.labels import RANDOM_SETS, SYSTEMS
from jaxais.labels import label as label_of

__all__ = ["check_trials", "check_types", "command_line", "plot_path", "trials"]


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
    plot: bool | str | os.PathLike[str] | None = None,
    label: str | None = None,
    world_scale: float = 1.0,
) -> tuple[str | os.PathLike[str], int, float, int]:
    """Check :func:`trials`'s arguments without loading JAX (one-line ``ValueError``\\ s naming
    the script's flags, every type before any range; a contender's spec by form, label and
    file); returns the world, the trial count and the two caps, defaults filled in."""
    check_types(out=out, world=world, trials=trials, seed=seed, random_set=random_set,
                seeds=seeds, plot=plot, label=label)  # fmt: skip
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
    if plot is True and out is None and _ipython() is None:
        raise ValueError(
            "plot=True shows the plot in a notebook (IPython), and none runs here, or draws "
            "beside out (OUT.png): give out, or a PNG path"
        )
    # A plot keeps every trajectory: a pose (3 float32) per 0.8 s, to 4000 s, held thrice.
    check_memory(n, RUN_BYTES + (180_000 if plot else 0), "--trials")
    if out is not None:
        check_output_file(out, (".json",))
    if plot_path(out, plot) is not None:
        check_output_file(plot_path(out, plot), (".png",))
    return world, n, tau_cap, collision_cap


def check_types(**args: Any) -> None:
    """ArgumentTypeError (one line, naming the flag) for the first of the drivers' common
    arguments (by keyword) of the wrong type; None is each one's default."""
    for name, value in args.items():
        if value is None:
            continue
        flag = f"--{name.replace('_', '-')}"
        if name in _INTEGERS:
            check_type(value, INTEGER, flag, "an integer")
        elif name in _SWITCHES:
            check_bool(value, flag)
        elif name == "plot":
            check_type(value, bool | PATH, flag, "True, False or a PNG path")
        elif name in _STRINGS:
            check_type(value, str, flag, "a string")
        else:  # a path
            check_path(value, flag, "a path")


_INTEGERS = {"trials", "seed", "generations", "slots", "steps", "robots", "every"}
_SWITCHES = {"progress", "resume", "evolve", "records", "share"}
_STRINGS = {"random_set", "label", "command", "system"}


def plot_path(out: str | os.PathLike[str] | None, plot: Any) -> Any:
    """Where :func:`trials` draws: ``plot`` itself, or for ``plot=True`` beside ``out`` (None
    without ``out``: then it only shows in the notebook)."""
    if plot is True:
        return None if out is None else Path(out).with_suffix(".png")
    return plot or None


def _ipython() -> Any:
    """The running IPython shell (a notebook's kernel), or None (IPython is not imported)."""
    return getattr(sys.modules.get("IPython"), "get_ipython", lambda: None)()


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
    plot: bool | str | os.PathLike[str] | None = None,
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
    ``contender``). ``plot`` (a bool or a path) also draws every trajectory (the trials then
    run as one batch): a path draws a PNG there; True shows it in the notebook (IPython) that
    runs this and, given ``out``, draws it beside it (``r.json`` -> ``r.png``); ``command`` is
    recorded (default: the ``trials.py`` line these arguments stand for). ``world_scale``
    scales the world and the camera's range (:func:`records.scaled_world`; not the real pen).
    Defaults are the paper's.
    """
    given = {"--world": world, "--tau-cap": tau_cap, "--collision-cap": collision_cap}
    world, n, tau_cap, collision_cap = check_trials(
        system, out, world=world, trials=trials, seed=seed, random_set=random_set, seeds=seeds,
        tau_cap=tau_cap, collision_cap=collision_cap, plot=plot, label=label,
        world_scale=world_scale)  # fmt: skip
    check_types(progress=progress, command=command)
    shown = plot is True and _ipython() is not None  # in a notebook: shown there too
    plot = plot_path(out, plot)
    contender = _is_contender(system)
    if command is None:
        spec = system if isinstance(system, str) else None
        flags = {"--system": None if contender else system, "--contender": spec if contender
                 else None, "--world": given["--world"], "--trials": trials, "--seed": seed
                 or None, "--random-set": random_set, "--seeds": seeds, "--tau-cap":
                 given["--tau-cap"], "--collision-cap": given["--collision-cap"], "--out": out,
                 "--plot": plot,
                 "--world-scale": None if world_scale == 1 else world_scale}  # fmt: skip
        command = command_line("trials.py", flags)
    # Imported after the arguments are checked: a bad one answers at once, without loading JAX.
    import jax
    from tqdm.auto import tqdm

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
    drawn = shown or plot is not None
    config = EpisodeConfig(tau_cap=tau_cap, collision_cap=collision_cap, record=drawn)
    network = NetworkParams()
    if contender:  # read before any run: a bad spec fails first
        c = one(system, label)
        name, systems, controller, seed_info = c.label, {c.label: c.params}, c.controller, None
    else:
        name, controller = label_of(system, random_set or "R1"), None
        systems, seed_info = build_systems([name], seeds, network)
    total, unit = (config.max_iterations(params.dt), "it") if drawn else (n, "run")
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
    if drawn:
        from jaxais.experiments.plotting import save_figure, show, world_figure

        trajs = results[name].trajectories
        # Each trial's boxes and goal where its world placed them (outlined in its colour).
        fig = world_figure(
            loaded,
            states=results[name].placements,
            trajectories=trajs,
            title=f"{name} in {loaded.name}",
            labels=[f"trial {i}" for i in range(len(trajs))],
        )
        if plot is not None:
            save_figure(fig, plot)
        if shown:
            show(fig)
    return doc
