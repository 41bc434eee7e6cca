"""The paper end to end (SPEC 9): every system in every world, Tables 3-5, H1-H4, the claims.

A world's systems run as one pool (process 0 writes in a multi-process run). ``out`` gets
tables.json, claims.json, report.md (figures/), run.json, trials/ (every trial; the drawn first
trials in WORLD_examples.npz; SIE at hold=1 in WORLD_SIE_hold1.json, the calibration point
beside the paper's 20 %) and manifest.json, a unit per world (``resume``).
"""

from __future__ import annotations

import json
import os
import shutil
import sys
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from jaxais import children
from jaxais.experiments import explanations, protocol
from jaxais.experiments.contenders import (
    Contender,
    check_specs,
    contender_config,
    neural,
    resolve,
)
from jaxais.experiments.one_system import check_types, command_line
from jaxais.io import (
    PATH,
    RUN_BYTES,
    Run,
    atomic_write,
    atomic_write_json,
    check_memory,
    check_path,
    check_type,
    open_run,
)
from jaxais.lock import scoped

__all__ = ["LTLRunError", "check_reproduce", "headline", "reproduce", "run_ltl"]

CALIBRATED = "SIE@hold=1"  # SIE selecting every iteration, on the plain label's streams


class LTLRunError(RuntimeError):
    """The LTL run (the GA) that ``evolve=True`` starts failed."""


def run_ltl(out: Path, seed: int, generations: int | None = None, resume: bool = False) -> Path:
    """Run the LTL (evolve.py's defaults, GA seed ``seed``) into ``out``; returns ``out/seed``.
    A child process, as the GA sets its own XLA flags before its JAX starts."""
    cmd = [sys.executable, "-m", "jaxais.scripts.evolve", "--out", str(out), "--seed", str(seed)]
    if generations is not None:
        cmd += ["--generations", str(generations)]
    if children.run(cmd + ["--resume"] * resume).returncode != 0:  # dies with this one
        raise LTLRunError("the LTL run (scripts/evolve.py) failed; see its message above")
    return out / "seed"


def _ltl_summary(seed_dir: Path) -> dict | None:
    """The evolve.py summary next to a seed (DIR/seed -> DIR/summary.json), if there is one."""
    for candidate in (seed_dir / "summary.json", seed_dir.parent / "summary.json"):
        if candidate.is_file():
            try:
                return json.loads(candidate.read_text())
            except (OSError, ValueError):
                return None
    return None


def check_reproduce(
    out: str | os.PathLike[str], *, trials: int | None = None, seed: int = 0,
    seeds: str | os.PathLike[str] | None = None, evolve: bool = False,
    generations: int | None = None, worlds: str | Sequence[str] | None = None,
    tau_cap: float | None = None, collision_cap: int | None = None, contenders: Any = None,
    world_scale: float = 1.0, explain: Sequence[str | os.PathLike[str]] = (),
) -> tuple[Path, list[str], float, int]:  # fmt: skip
    """:func:`reproduce`'s arguments checked without JAX (one-line ValueErrors naming the
    flags, every type before any range; ``contenders``' specs by form, label and file) ->
    (out, worlds, tau_cap, collision_cap), defaults filled in."""
    check_path(out, "--out", "a folder's path")
    check_types(trials=trials, seed=seed, seeds=seeds, evolve=evolve, generations=generations)
    names = protocol.check_worlds(worlds)
    if isinstance(contenders, str | list | tuple) and all(isinstance(c, str) for c in contenders):
        check_specs(contenders)
    protocol.check_seed(seed)
    protocol.check_world_scale(world_scale, [n for n in names if n != protocol.REAL_WORLD])
    explanations.load(explain)  # each file read and checked, before any trial
    if trials is not None and trials < 2:
        raise ValueError(f"--trials must be >= 2 (t-tests need two per group), got {trials}")
    if trials is not None:  # a world's systems, SIE at hold=1 and the baseline: one pool
        runs = max(len(protocol.systems_for_world(w)) for w in names) + 2
        check_memory(trials, runs * RUN_BYTES, "--trials")
    tau_cap, collision_cap = protocol.check_caps(tau_cap, collision_cap)
    if generations is not None and not evolve:
        raise ValueError("--generations caps the LTL run of --evolve: give both, or neither")
    if generations is not None and generations < 1:
        raise ValueError(f"--generations must be >= 1, got {generations}")
    if evolve and seeds is not None:
        raise ValueError("--seeds and --evolve exclude each other: the LTL makes the seed")
    return Path(out), names, tau_cap, collision_cap


@scoped  # its folder's lock goes when it returns or raises
def reproduce(
    out: str | os.PathLike[str], *, trials: int | None = None, seed: int = 0,
    seeds: str | os.PathLike[str] | None = None, evolve: bool = False,
    generations: int | None = None, baseline: str | os.PathLike[str] | bool = True,
    worlds: str | Sequence[str] | None = None, tau_cap: float | None = None,
    collision_cap: int | None = None, progress: bool = True, command: str | None = None,
    resume: bool = False, contenders: Any = None, world_scale: float = 1.0,
    explain: Sequence[str | os.PathLike[str]] = (),
) -> dict[str, Any] | None:  # fmt: skip
    """Run the paper's experiments into ``out`` (the flags of scripts/reproduce.py).

    Args:
        evolve: run the LTL first (:func:`run_ltl`, into ``out/ltl``) and use its seed.
        baseline: the neural controller, the contender ``NN``: True (the shipped weights), a
            folder of weights, or False.
        contenders: controllers beyond the paper, each run in every world in a pool of its own
            beside the paper's systems (:mod:`jaxais.experiments.contenders`): a dict label ->
            ``(controller, params)`` or spec ``FILE.py:NAME``, or a list of specs.
        worlds: the paper's worlds by name, or world files (``PATH.toml``), comma-separated.
        command: recorded in run.json (default: the reproduce.py line these arguments mean).
        world_scale: every world but the real pen (whose size the paper gives) and the camera's
            range scaled so (:func:`records.scaled_world`) [ours: 1].
        explain: what the report's "why" column reads (:mod:`.explanations`): a run of more
            trials (its folder), the seeds ledger (``seeds.json``), a robustness map
            (``robustness.json``); not a setting of the run (a ``resume`` may add them).
        resume: finish the partial run in ``out``, giving the uninterrupted run's results.

    Returns:
        ``{"tables", "claims", "run", "report"}`` on the writing process, else None.

    Raises:
        ValueError: a bad argument, folder, seed or weights (before any trial).
        LTLRunError: the LTL run failed.
    """
    checked = check_reproduce(
        out, trials=trials, seed=seed, seeds=seeds, evolve=evolve, generations=generations,
        worlds=worlds, tau_cap=tau_cap, collision_cap=collision_cap,
        contenders=contenders, world_scale=world_scale, explain=explain)  # fmt: skip
    check_type(baseline, bool | PATH, "--baseline", "True, False or a folder of weights")
    check_types(progress=progress, command=command, resume=resume)
    if command is None:
        flags = {"--out": out, "--trials": trials, "--seeds": seeds, "--evolve": evolve,
                 "--seed": seed or None, "--baseline": None if isinstance(baseline, bool)
                 else baseline, "--no-baseline": baseline is False,
                 "--worlds": worlds if isinstance(worlds, str | None) else ",".join(
                 map(str, worlds)), "--tau-cap": tau_cap, "--collision-cap": collision_cap,
                 "--generations": generations,
                 "--world-scale": None if world_scale == 1 else world_scale}  # fmt: skip
        command = command_line("reproduce.py", flags) + _contender_flags(contenders)
        command += "".join(f" --explain {e}" for e in explain)
    out, names, tau_cap, collision_cap = checked
    evidence = explanations.load(explain)
    import jax

    # Process 0 of a multi-process run writes (and checks the folder); the others read it.
    lead = not jax.distributed.is_initialized() or jax.process_index() == 0
    from jaxais import envs
    from jaxais.experiments.records import load_ltl_seed

    # Read first: a missing or corrupt seed, world file, baseline or contender fails before
    # anything is written.
    loaded = None if evolve else load_ltl_seed(seeds)
    worlds_by_key = _load_worlds(names, envs, world_scale)
    given = resolve(contenders)
    entrants = given
    if baseline is not False:
        try:
            nn = neural(None if baseline is True else baseline)
        except ValueError as err:
            raise ValueError(f"--baseline: {err}") from None
        if nn.label in {c.label for c in given}:
            raise ValueError(f"--contender: label {nn.label!r} is the neural baseline's")
        entrants = [nn, *given]
    config = {"trials": trials, "seed": seed, "seeds": None if seeds is None else str(seeds),
              "evolve": evolve, "generations": generations, "baseline": baseline if isinstance(
              baseline, bool) else str(baseline), "worlds": names, "tau_cap": tau_cap,
              "collision_cap": collision_cap}  # fmt: skip
    if given:  # recorded only when given: earlier runs' manifests stay valid
        config["contenders"] = {c.label: c.source for c in given}
    if world_scale != 1:  # so too the world scale
        config["world_scale"] = float(world_scale)
    run = open_run(out, "reproduce", config, resume=resume, write=lead)

    started = time.perf_counter()
    timings: dict[str, float] = {}
    if evolve:
        ltl = run.out / "ltl"
        if "ltl" not in run.units:
            from jaxais.experiments.seeds import ltl_state

            t, state = time.perf_counter(), ltl_state(ltl)
            if state == "fresh" and ltl.exists():
                shutil.rmtree(ltl)  # this run's own LTL, killed before its first checkpoint
            if state != "done":
                run_ltl(ltl, seed, generations, resume=state == "resume")
            run.finish("ltl", {"ltl_s": time.perf_counter() - t})
        timings["ltl_s"] = run.units["ltl"]["ltl_s"]
        seeds = ltl / "seed"
        loaded = load_ltl_seed(seeds)
    return _run(run, worlds_by_key, trials, seed, seeds, loaded, entrants, tau_cap,
                collision_cap, progress=progress, command=command, started=started,
                timings=timings, lead=lead, evidence=evidence)  # fmt: skip


def _load_worlds(names: list[str], envs: Any, scale: float = 1.0) -> dict[str, tuple]:
    """key -> (what ``--worlds`` named, the World, its scale): the paper's worlds by name, a
    world file by its world's name, which must be new (one-line error otherwise); every world
    but the real pen at ``scale``."""
    out = {}
    for name in names:
        at = 1.0 if name == protocol.REAL_WORLD else scale
        world = envs.load_world(name, scale=at) if at != 1 else envs.load_world(name)
        key = name if name in protocol.WORLDS else world.name
        if key in out or (name not in protocol.WORLDS and key in protocol.WORLDS):
            raise ValueError(
                f"--worlds: {name} names its world {key!r}, as another world of the run is "
                "named: give the file's world another name"
            )
        out[key] = (name, world, at)
    return out


def _contender_flags(contenders: Any) -> str:
    """The ``--contender`` flags of specs given from Python, for the recorded command."""
    specs = [contenders] if isinstance(contenders, str) else contenders
    if isinstance(specs, list | tuple) and all(isinstance(c, str) for c in specs):
        return "".join(f" --contender {c}" for c in specs)
    if isinstance(specs, dict) and all(isinstance(c, str) for c in specs.values()):
        return "".join(f" --contender {k}={c}" for k, c in specs.items())
    return ""


def _run(run: Run, worlds: dict[str, tuple[str, Any]], n_trials: int | None, seed: int,
         seeds: str | os.PathLike[str] | None, loaded: tuple, entrants: list[Contender],
         tau_cap: float, collision_cap: int, *, progress: bool, command: str, started: float,
         timings: dict[str, float], lead: bool,
         evidence: Any = None) -> dict[str, Any] | None:  # fmt: skip
    """:func:`reproduce` once checked and read (``worlds``: key -> (source, World); the
    contenders): every world not finished in ``run``, then the tables, claims and report."""
    import numpy as np
    from tqdm.auto import tqdm

    from jaxais.experiments import claims, report, stats
    from jaxais.experiments.plotting import draw_world
    from jaxais.experiments.records import (
        build_systems,
        portable_command,
        results_document,
        run_config,
        scaled_params,
        versions,
    )
    from jaxais.immune.network import NetworkParams
    from jaxais.loop import EpisodeConfig
    from jaxais.seed import default_seed_dir
    from jaxais.trials import Placement, run_trials

    out = run.out
    seeds_dir = Path(seeds) if seeds else default_seed_dir()

    network = NetworkParams()
    config = EpisodeConfig(tau_cap=tau_cap, collision_cap=collision_cap)
    # The first trial of each system runs again recorded (same keys: same run), to be drawn.
    example = EpisodeConfig(tau_cap=tau_cap, collision_cap=collision_cap, record=True)
    results_by_world, contenders_by_world, trajectories, placements, configs = {}, {}, {}, {}, {}
    calibration_by_world = {}
    (out / "trials").mkdir(exist_ok=True)
    for name, (source, world, scale) in worlds.items():
        labels = list(protocol.systems_for_world(name))
        n = n_trials if n_trials is not None else protocol.trials_for_world(name)
        systems, seed_info = build_systems(labels, seeds_dir, network, loaded)
        params = scaled_params(scale)  # the camera's range [ours] grows with the world
        cfg = run_config(world, source, config, network, params, seed_info, scale)
        configs[name] = cfg
        hold1_cfg = {**cfg, "readings": {**cfg["readings"], "hold": 1}}
        files = {label: (label, cfg) for label in labels} | {"SIE_hold1": (CALIBRATED, hold1_cfg)}
        files |= {c.label: (c.label, contender_config(cfg, c.source)) for c in entrants}
        if name in run.units:  # a finished world: its trials and examples from its files
            if not lead:
                continue
            world_t = run.units[name]
            records = {
                key: json.loads((out / "trials" / f"{name}_{key}.json").read_text())["trials"]
                for key in files
            }
            with np.load(out / "trials" / f"{name}_examples.npz") as z:
                trajectories[name] = {k: z[f"path:{k}"] for k in labels}
                placements[name] = {k: Placement(z[f"boxes:{k}"], z[f"goal:{k}"]) for k in labels}
        else:
            sie = systems["SIE"]
            hold1 = {CALIBRATED: sie.replace(readings=sie.readings.replace(hold=np.int32(1)))}
            world_t = {}
            k = len(labels) + 1 + len(entrants)
            with tqdm(total=n * k, desc=f"{name}: {k} systems x {n} trials", unit="run",
                      file=sys.stderr, disable=not (lead and progress)) as bar:  # fmt: skip
                sets = run_trials(world, systems | hold1, n, seed, config, params, bar, world_t)
                sets["SIE_hold1"] = sets.pop(CALIBRATED)
                for c in entrants:  # each in a pool of its own: the paper's records cannot move
                    sets |= run_trials(
                        world, {c.label: c.params}, n, seed, config, params, bar, world_t,
                        controller=c.controller,
                    )  # fmt: skip
            first = run_trials(world, systems, 1, seed, example, params, None, world_t)
            trajectories[name] = {k: v.trajectories[0][:, :2] for k, v in first.items()}
            placements[name] = {k: v.placements[0] for k, v in first.items()}
            if not lead:
                continue
            records = {key: ts.records for key, ts in sets.items()}
            # The world's unit: every trials file and the drawn examples, then the manifest.
            for key, (label, doc_cfg) in files.items():
                doc = results_document(label, name, seed, sets[key], doc_cfg)
                atomic_write_json(out / "trials" / f"{name}_{key}.json", doc)
            arrays = {f"path:{k}": v for k, v in trajectories[name].items()}
            for k, p in placements[name].items():
                arrays |= {f"boxes:{k}": p.boxes, f"goal:{k}": p.goal}
            atomic_write(
                out / "trials" / f"{name}_examples.npz", lambda t, a=arrays: np.savez(t, **a)
            )
            run.finish(name, world_t)
        for key, value in world_t.items():
            timings[f"{name}_{key}"] = value
            timings[key] = timings.get(key, 0.0) + value
        results_by_world[name] = {k: records[k] for k in labels}
        calibration_by_world[name] = {"SIE": records["SIE_hold1"]}
        if entrants:
            contenders_by_world[name] = {c.label: records[c.label] for c in entrants}

    if not lead:
        return None
    t = time.perf_counter()
    cis = stats.table3_ci(results_by_world)  # once, for the tables and the claims
    tables = stats.build_tables(results_by_world, cis=cis)
    tables["calibration"] = stats.calibration(
        results_by_world, calibration_by_world, {"k1": network.k1, "k2": network.k2}
    )
    if contenders_by_world:
        tables["contenders"] = stats.contender_tables(results_by_world, contenders_by_world)
        tables["contenders"]["contenders"] = {c.label: c.source for c in entrants}
    # c counted per reading (section 4.1) beside the default, from the same records.
    rules = stats.rule_tables(results_by_world, collision_cap)
    if rules:
        tables["by_rule"] = rules
    atomic_write_json(out / "tables.json", tables)
    ledger = claims.claims(results_by_world, cis=cis)
    claims_doc = claims.document(ledger)
    rule_claims = claims.by_rule(results_by_world, collision_cap)
    if rule_claims:
        claims_doc["by_rule"] = rule_claims
    timings["statistics_s"] = time.perf_counter() - t
    atomic_write_json(out / "claims.json", claims_doc)
    timings["total_s"] = time.perf_counter() - started
    run_doc = {
        "command": portable_command(command),
        "seed": seed,
        "trials": n_trials,
        "ltl_seed": loaded[1],
        "worlds": configs,
        "versions": versions(),
        "timings_s": timings,
    }
    if entrants:
        run_doc["contenders"] = {c.label: c.source for c in entrants}
    atomic_write_json(out / "run.json", run_doc)
    drawn = {name: world for name, (_, world, _) in worlds.items()}
    report_path = report.write_report(
        out,
        tables,
        results_by_world,
        report.load_paper_tables(),
        _ltl_summary(seeds_dir),
        {k: v for k, v in run_doc.items() if k != "timings_s"},
        timings,
        trajectories,
        lambda ax, world_name, placement=None: draw_world(ax, drawn[world_name], placement),
        claims_ledger=ledger,
        example_placements=placements,
        contenders=tables.get("contenders"),
        contender_results=contenders_by_world,
        rule_claims={r: doc["claims"] for r, doc in rule_claims.items()},
        evidence=evidence,
    )
    run.complete()
    return {"tables": tables, "claims": claims_doc, "run": run_doc, "report": report_path}


def headline(result: Mapping[str, Any]) -> str:
    """One line: claims reproduced, H1-H4's verdicts, time taken, the report's path."""

    verdicts = ", ".join(
        f"{h} {'supported' if v['supported'] else 'not supported'}"
        for h, v in result["tables"]["hypotheses"].items()
    )
    counts, ci_counts = result["claims"]["summary"], result["claims"]["ci_summary"]
    timings = result["run"]["timings_s"]
    return (
        f"{counts['reproduced']} of {counts['evaluated']} evaluated claims reproduced "
        f"({counts['total']} in all; {ci_counts['reproduced_with_ci']} of them with separated "
        f"95 % CIs, {ci_counts['contradicted_with_ci']} contradicted by them); {verdicts}. "
        f"Total {timings['total_s']:.0f} s. "
        f"Report: {result['report']}"
    )
