"""Train the neural baseline and run it beside SIE and HDC in the paper's worlds [ours].

Free of JAX at import (it loads on the first call). Never writes into the shipped
``checkpoints/`` unless asked to (``into_checkpoints=True``).
"""

from __future__ import annotations

import dataclasses
import sys
import tempfile
import time
from collections.abc import Sequence
from importlib import resources
from pathlib import Path
from typing import Any

from jaxais import io
from jaxais.baselines.config import NN_LABEL, TrainConfig
from jaxais.experiments import protocol
from jaxais.io import UserError, atomic_write_json, atomic_write_text, open_run, read_json_object
from jaxais.lock import scoped

REFERENCE = ("SIE", "HDC")  # the paper's systems it runs beside


def _output_dir(out: str | Path, into_checkpoints: bool, make: bool = True) -> Path:
    """``out``, created and writable (``make``); refused inside the shipped checkpoints/ unless
    asked."""
    out = Path(out)
    shipped = Path(str(resources.files("jaxais.checkpoints"))).resolve()
    if not into_checkpoints and shipped in (out.resolve(), *out.resolve().parents):
        raise ValueError(f"{out}: in the shipped checkpoints/ (--into-checkpoints to write there)")
    if not make:
        return out
    out.mkdir(parents=True, exist_ok=True)
    tempfile.TemporaryFile(dir=out).close()  # writable: fail now, not after the work
    return out


def _check_weights(weights: str | Path | None) -> None:
    """Weights to evaluate, read now: missing or damaged ones are refused before the run's
    folder is made."""
    if weights is None:
        return
    if not (Path(weights) / "params.npz").is_file():
        raise ValueError(f"{weights}: no params.npz to evaluate (train first)")
    from jaxais.baselines.neural import load_params

    load_params(weights)


def _versions() -> dict[str, str]:
    """The run's versions (:func:`jaxais.experiments.records.versions`) and optax's."""
    import optax

    from jaxais.experiments.records import versions

    return versions() | {"optax": optax.__version__}


def train_baseline(
    out: str | Path,
    config: TrainConfig | None = None,
    *,
    seed: int = 0,
    log_every: int = 10,
    command: str | None = None,
    into_checkpoints: bool = False,
) -> dict[str, Any]:
    """Train the MLP by OpenES, a stderr line every ``log_every`` generations; write params.npz,
    config.json (returned) and training_curve.png into ``out``. Bad arguments: ValueError."""
    protocol.check_seed(seed)
    if log_every < 1:
        raise ValueError(f"--log-every must be >= 1, got {log_every}")
    config = TrainConfig() if config is None else config
    out = _output_dir(out, into_checkpoints)
    import jax
    import numpy as np

    from jaxais.baselines.neural import make_train, save_params

    start = time.perf_counter()
    first: list[float] = []

    def log(gen, metrics) -> None:
        gen = int(gen)
        if not first:
            first.append(time.perf_counter() - start)  # compile + first generation
        if gen % log_every == 0 or gen == config.generations - 1:
            m = {k: float(v) for k, v in metrics.items()}
            print(
                f"[{time.perf_counter() - start:7.1f} s] gen {gen + 1:4d}/{config.generations}: "
                f"centre fitness {m['center_fitness']:7.2f} (finished "
                f"{100 * m['center_finished']:3.0f} %, c {m['center_collisions']:.2f}), "
                f"population mean {m['fitness_mean']:7.2f}, best {m['fitness_best']:7.2f}",
                file=sys.stderr,
                flush=True,
            )

    result = make_train(config, log)(jax.random.key(seed))
    metrics = {k: np.asarray(v) for k, v in jax.device_get(result.metrics).items()}
    wall = time.perf_counter() - start
    tail = max(1, config.generations // 10)
    ends = ("center_fitness", "center_finished", "center_collisions")  # means of the last tenth
    last = {f"{k}_last_{tail}": float(metrics[k][-tail:].mean()) for k in ends}
    info = {
        "format": "jaxais-neural/1",
        "command": command,
        "seed": seed,
        "config": dataclasses.asdict(config),
        "population": config.population,
        "parameters": int(sum(np.size(x) for x in jax.tree.leaves(result.params))),
        "fitness_sign": "lower is better: minus the mean episode return",
        "wall_s": round(wall, 1),
        "first_generation_s": round(first[0], 1) if first else None,
        "devices": len(jax.local_devices()),
        "final": {"center_fitness": float(metrics["center_fitness"][-1]), **last},
        "curve": {k: [round(float(x), 4) for x in v] for k, v in metrics.items()},
        "versions": _versions(),
    }
    save_params(out, result.params, info)
    _plot_curve(metrics, config, out / "training_curve.png")
    return info


def _plot_curve(metrics: dict[str, Any], config: TrainConfig, path: Path) -> None:
    import numpy as np

    from jaxais.experiments.plotting import new_figure, save_figure

    gens = np.arange(1, len(metrics["center_fitness"]) + 1)
    fig = new_figure((8, 5.5))
    top, bottom = fig.subplots(2, 1, sharex=True)
    top.plot(gens, metrics["fitness_mean"], lw=1, color="0.6", label="population mean")
    top.plot(gens, metrics["fitness_best"], lw=1, color="tab:green", label="population best")
    top.plot(gens, metrics["center_fitness"], lw=1.5, color="tab:blue", label="search mean")
    top.set_ylabel("fitness (- return; lower is better)")
    top.legend(loc="upper right", fontsize=8)
    top.set_title(
        f"OpenES in {config.world}: {config.population} members x {config.episodes} episodes "
        f"x {config.steps} steps"
    )
    bottom.plot(gens, 100 * metrics["center_finished"], color="tab:blue", label="found target, %")
    twin = bottom.twinx()
    twin.plot(gens, metrics["center_collisions"], color="tab:red", lw=1, label="collisions")
    bottom.set_ylabel("search mean: found target (%)", color="tab:blue")
    twin.set_ylabel("collisions per episode", color="tab:red")
    bottom.set_xlabel("generation")
    save_figure(fig, path)


def evaluate_baseline(
    weights: str | Path | None,
    out: str | Path,
    *,
    seed: int = 0,
    seeds: str | Path | None = None,
    command: str | None = None,
    into_checkpoints: bool = False,
) -> dict[str, Any]:
    """Run the controller in ``weights`` (None: shipped), SIE (``seeds``) and HDC in the paper's
    worlds, trials and episode; write evaluation.json (returned: trials, summaries, NN-vs-SIE/HDC
    tests of f) and evaluation.md into ``out``."""
    protocol.check_seed(seed, "--eval-seed")
    _check_weights(weights)
    out = _output_dir(out, into_checkpoints)
    from tqdm.auto import tqdm

    from jaxais import envs
    from jaxais.baselines.neural import NEURAL, load_params
    from jaxais.experiments import stats
    from jaxais.experiments.records import build_systems
    from jaxais.immune.network import NetworkParams
    from jaxais.trials import STL_CONFIG, run_trials, summarise

    params, info = load_params(weights)
    systems, seed_info = build_systems(list(REFERENCE), seeds, NetworkParams())
    sim = envs.default_params()
    doc: dict[str, Any] = {
        "command": command,
        "seed": seed,
        "weights": {"config": info.get("config"), "seed": info.get("seed")},
        "ltl_seed": seed_info,
        "episode": dataclasses.asdict(STL_CONFIG),
        "versions": _versions(),
        "worlds": {},
        "timings_s": {},
    }
    for name in protocol.WORLDS:
        world = envs.load_world(name)
        n = protocol.trials_for_world(name)
        t0 = time.perf_counter()
        total = n * (len(systems) + 1)  # runs (the trials go through a refilling pool)
        with tqdm(total=total, desc=f"{name}", unit="run", file=sys.stderr) as bar:
            results = run_trials(world, systems, n, seed, STL_CONFIG, sim, bar)
            results |= run_trials(
                world, {NN_LABEL: params}, n, seed, STL_CONFIG, sim, bar, controller=NEURAL
            )
        doc["timings_s"][name] = round(time.perf_counter() - t0, 1)
        systems_doc = {k: {"summary": summarise(v.records), "trials": v.records}
                       for k, v in results.items()}  # fmt: skip
        f = {label: stats.metric_values(ts.records, "f") for label, ts in results.items()}
        tests = {}
        for other in REFERENCE:
            t, p = stats.welch_t(f[NN_LABEL], f[other])
            u, p_u = stats.mann_whitney_u(f[NN_LABEL], f[other])
            tests[f"{NN_LABEL} vs {other}"] = {"metric": "f", "welch_t": t, "welch_p": p,
                "mann_whitney_u": u, "mann_whitney_p": p_u,
                "significant_99": bool(p < protocol.ALPHA)}  # fmt: skip
        doc["worlds"][name] = {"systems": systems_doc, "tests": tests}

    atomic_write_json(out / "evaluation.json", stats.jsonable(doc))
    atomic_write_text(out / "evaluation.md", _table(doc, info))
    return doc


@scoped  # its folder's lock goes when it returns or raises
def baseline(
    out: str | Path,
    config: TrainConfig | None = None,
    *,
    train: bool = True,
    evaluate: bool = True,
    seed: int = 0,
    eval_seed: int = 0,
    weights: str | Path | None = None,
    seeds: str | Path | None = None,
    log_every: int = 10,
    command: str | None = None,
    into_checkpoints: bool = False,
    resume: bool = False,
) -> tuple[dict[str, Any] | None, dict[str, Any] | None]:
    """``scripts/train_baseline.py``: :func:`train_baseline` then :func:`evaluate_baseline` of
    the new weights (or ``weights`` without ``train``) into ``out``, each stage a unit of its
    manifest (``resume``). Returns (config.json's document, evaluation.json's), None if skipped.
    """
    config = TrainConfig() if config is None else config
    if train:  # a generation's episodes run at once, each with its member's 13 weights a unit
        io.check_memory(config.pairs * config.episodes, 2 * io.RUN_BYTES, "--pairs x --episodes")
        io.check_memory(config.hidden, 104 * config.pairs * config.episodes, "--hidden")
        io.check_memory(config.generations, 64, "--generations")  # keys and metrics, each
    if evaluate and not train:
        _check_weights(weights)  # before anything is written
    out = _output_dir(out, into_checkpoints, make=False)  # open_run makes it
    settings = {"train": dataclasses.asdict(config) if train else None, "seed": seed,
                "evaluate": evaluate, "eval_seed": eval_seed, "seeds": seeds and str(seeds),
                "weights": weights and str(weights)}  # fmt: skip
    folder = open_run(out, "train_baseline", settings, resume=resume)
    info = doc = None
    if train and "train" in folder.units:  # finished before an interruption
        info = read_json_object(out / "config.json")
    elif train:
        info = train_baseline(out, config, seed=seed, log_every=log_every, command=command,
                              into_checkpoints=into_checkpoints)  # fmt: skip
        folder.finish("train")
    if evaluate and "evaluate" in folder.units:
        doc = read_json_object(out / "evaluation.json")
    elif evaluate:
        doc = evaluate_baseline(out if train else weights, out, seed=eval_seed, seeds=seeds,
                                command=command, into_checkpoints=into_checkpoints)  # fmt: skip
        folder.finish("evaluate")
    folder.complete()
    return info, doc


def _p(p: float) -> str:
    return f"{p:.2g}" if p >= 1e-4 else f"{p:.1e}"


def _table(doc: dict[str, Any], info: dict[str, Any]) -> str:
    """The evaluation as markdown: Table 3/5-style rows and the tests of f."""
    lines = [
        "| World | System | n | c | τ (s) | f | failed (%) | trapped (s) |",
        "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    for world, entry in doc["worlds"].items():
        for label in (*REFERENCE, NN_LABEL):
            s = entry["systems"][label]["summary"]
            lines.append(
                f"| {world} | {label} | {s['n']} | {s['collisions']:.2f} | {s['tau']:.1f} | "
                f"{s['fitness']:.1f} | {100 * s['failure_rate']:.0f} | {s['trapped_s']:.1f} |"
            )
    lines += [
        "",
        "| World | Comparison of f | Welch t | p | Mann-Whitney U | p | p < 0.01 |",
        "| --- | --- | ---: | ---: | ---: | ---: | :---: |",
    ]
    for world, entry in doc["worlds"].items():
        for name, t in entry["tests"].items():
            tv = "inf" if t["welch_t"] is None else f"{t['welch_t']:.2f}"
            lines.append(
                f"| {world} | {name} | {tv} | {_p(t['welch_p'])} | {t['mann_whitney_u']:.0f} | "
                f"{_p(t['mann_whitney_p'])} | {'yes' if t['significant_99'] else 'no'} |"
            )
    cfg = info.get("config", {})
    lines += [
        "",
        f"Lower is better (c collisions capped at {protocol.COLLISION_CAP}, τ capped at "
        f"{protocol.TAU_CAP:g} s, f = (8c + τ)/2). Trials' seed {doc['seed']}; NN trained in "
        f"{cfg.get('world')} (seed {info.get('seed')}, {info.get('wall_s')} s wall).",
        "",
    ]
    return "\n".join(lines)


def _entry(doc: Any, path: Path, *keys: str) -> Any:
    """``doc[keys[0]][keys[1]]...``, or a UserError naming the first missing entry."""
    for i, key in enumerate(keys):
        if not isinstance(doc, dict) or key not in doc:
            where = "/".join(keys[: i + 1])
            raise UserError(f"{path}: no entry {where} (not a train_baseline.py evaluation)")
        doc = doc[key]
    return doc


def collect_baselines(dirs: Sequence[str | Path]) -> str:
    """One markdown table of evaluated runs' mean f and failure rate per world (SIE and HDC
    from the first run); several runs' NN trials are also pooled and tested against SIE's."""
    import numpy as np

    from jaxais.experiments import stats

    ok = lambda t: (
        isinstance(t, dict)
        and isinstance(t.get("failed"), bool)
        and isinstance(t.get("fitness"), int | float)
    )

    runs, worlds = [], None
    for d in dirs:
        path = Path(d) / "evaluation.json"
        ev, info = read_json_object(path), read_json_object(Path(d) / "config.json")
        worlds = list(_entry(ev, path, "worlds")) if worlds is None else worlds
        if not worlds:
            raise UserError(f"{path}: evaluated in no world")
        for w, label in ((w, label) for w in worlds for label in (*REFERENCE, NN_LABEL)):
            trials = _entry(ev, path, "worlds", w, "systems", label, "trials")
            if not isinstance(trials, list) or not trials or not all(map(ok, trials)):
                raise UserError(f"{path}: {w} {label} holds no trials with fitness and failed")
        runs.append((ev, info))
    head = "| System | training seed | maze fitness | " + " | ".join(
        f"{w} f (failed %)" for w in worlds
    )
    lines = [head + " |", "| --- | ---: | ---: |" + " ---: |" * len(worlds)]

    def cell(trials: list[dict]) -> str:
        f = np.mean([t["fitness"] for t in trials])
        return f"{f:.1f} ({100 * np.mean([t['failed'] for t in trials]):.0f})"

    for label in REFERENCE:
        row = [cell(runs[0][0]["worlds"][w]["systems"][label]["trials"]) for w in worlds]
        lines.append(f"| {label} | – | – | " + " | ".join(row) + " |")
    pooled: dict[str, list[dict]] = {w: [] for w in worlds}
    for ev, info in runs:
        final = info.get("final") if isinstance(info.get("final"), dict) else {}
        maze = next((v for k, v in final.items() if k.startswith("center_fitness_last")), None)
        row = []
        for w in worlds:
            trials = ev["worlds"][w]["systems"][NN_LABEL]["trials"]
            pooled[w] += trials
            row.append(cell(trials))
        m = "–" if maze is None else f"{maze:.1f}"
        lines.append(f"| {NN_LABEL} | {info.get('seed')} | {m} | " + " | ".join(row) + " |")
    if len(runs) > 1:
        row = [cell(pooled[w]) for w in worlds]
        lines.append(
            f"| {NN_LABEL}, all {len(runs)} runs pooled | – | – | " + " | ".join(row) + " |"
        )
        lines += [
            "",
            f"| World | pooled {NN_LABEL} vs SIE, mean f | median {NN_LABEL} | median SIE | "
            "Welch p | Mann-Whitney p |",
            "| --- | :---: | ---: | ---: | ---: | ---: |",
        ]
        for w in worlds:
            nn = stats.metric_values(pooled[w], "f")
            sie = stats.metric_values(runs[0][0]["worlds"][w]["systems"]["SIE"]["trials"], "f")
            _, p_t = stats.welch_t(nn, sie)
            _, p_u = stats.mann_whitney_u(nn, sie)
            lower = "lower" if nn.mean() < sie.mean() else "higher"
            lines.append(
                f"| {w} | {lower} | {np.median(nn):.1f} | {np.median(sie):.1f} | {_p(p_t)} | "
                f"{_p(p_u)} |"
            )
    return "\n".join(lines) + "\n"
