"""Train the neural baseline (an MLP, by OpenES); run it beside SIE and HDC in the paper's worlds.

    python scripts/train_baseline.py                          # train (defaults), then evaluate
    python scripts/train_baseline.py --eval-only              # evaluate the shipped weights
    python scripts/train_baseline.py --out /tmp/nn --generations 20 --no-eval
    python scripts/train_baseline.py --collect checkpoints/neural runs/nn-seed1   # one table

Training (jaxais.baselines.neural.make_train, one compiled program) logs a line every
``--log-every`` generations and writes, into ``--out`` (default: the checkout's
checkpoints/neural), params.npz (the weights), config.json (the TrainConfig, seed, versions,
wall time, final training fitness) and training_curve.png. The evaluation runs the trained
controller, SIE (the shipped LTL seed, or ``--seeds``) and HDC in world1, world2 and real with
the paper's trial counts and caps and the trials' seed ``--eval-seed`` (the reproduction's is 0),
then writes evaluation.json (every trial, the summaries, NN-vs-SIE and NN-vs-HDC tests of f) and
evaluation.md (the tables) into ``--out``.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path
from typing import Any

from jaxais.baselines.config import NN_LABEL, TrainConfig
from jaxais.cli import (
    ArgumentParser,
    UserError,
    atomic_write_json,
    atomic_write_text,
    check_writable_dir,
    main_wrapper,
    run_script,
)
from jaxais.experiments import protocol

BUILTIN_WORLDS = ("ga_maze", "world1", "world2", "real")
"""The simulator's built-in worlds (``envs.BUILTIN_WORLDS``, named here without loading JAX)."""
DEFAULT_OUT = Path(__file__).resolve().parents[1] / "checkpoints" / "neural"
REFERENCE = ("SIE", "HDC")
"""The paper's systems it runs beside."""
_DEFAULTS = TrainConfig()


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = ArgumentParser(prog="train_baseline.py", description=__doc__.split("\n\n")[0])
    p.add_argument("--out", default=str(DEFAULT_OUT), help="weights and results directory")
    p.add_argument("--seed", type=int, default=0, help="PRNG seed of the training")
    p.add_argument("--eval-seed", type=int, default=0, help="PRNG seed of the trials")
    p.add_argument("--eval-only", action="store_true", help="evaluate the weights in --out")
    p.add_argument("--no-eval", action="store_true", help="train only")
    p.add_argument("--seeds", default=None, help="LTL seed directory for SIE (default: shipped)")
    p.add_argument("--log-every", type=int, default=10, help="generations per log line")
    p.add_argument(
        "--collect",
        nargs="+",
        metavar="DIR",
        default=None,
        help="print one table of several evaluated runs (e.g. training seeds) and exit",
    )
    g = p.add_argument_group("training (TrainConfig; defaults [ours])")
    g.add_argument("--world", default=_DEFAULTS.world, help="training world")
    for name, kind in (
        ("generations", int),
        ("pairs", int),
        ("episodes", int),
        ("steps", int),
        ("sigma", float),
        ("learning_rate", float),
        ("hidden", int),
        ("weight_decay", float),
        ("collision_penalty", float),
    ):
        default = getattr(_DEFAULTS, name)
        g.add_argument(f"--{name.replace('_', '-')}", type=kind, default=default,
                       help=f"default {default}")  # fmt: skip
    return p.parse_args(argv)


def train_config(args: argparse.Namespace) -> TrainConfig:
    names = [f.name for f in dataclasses.fields(TrainConfig)]
    try:
        return TrainConfig(**{n: getattr(args, n) for n in names})
    except ValueError as err:
        raise UserError(f"--{str(err).replace('_', '-')}") from err


def versions() -> dict[str, str]:
    """The run's versions (:func:`jaxais.experiments.records.versions`) and optax's."""
    import optax

    from jaxais.experiments.records import versions as run_versions

    return run_versions() | {"optax": optax.__version__}


# ------------------------------------------------------------------------------------ training


def train(args: argparse.Namespace, config: TrainConfig, command: str) -> None:
    import jax
    import numpy as np

    from jaxais.baselines.neural import make_train, save_params

    start = time.perf_counter()
    first: list[float] = []

    def log(gen, metrics) -> None:
        gen = int(gen)
        if not first:
            first.append(time.perf_counter() - start)  # compile + first generation
        if gen % args.log_every == 0 or gen == config.generations - 1:
            m = {k: float(v) for k, v in metrics.items()}
            print(
                f"[{time.perf_counter() - start:7.1f} s] gen {gen + 1:4d}/{config.generations}: "
                f"centre fitness {m['center_fitness']:7.2f} (finished "
                f"{100 * m['center_finished']:3.0f} %, c {m['center_collisions']:.2f}), "
                f"population mean {m['fitness_mean']:7.2f}, best {m['fitness_best']:7.2f}",
                file=sys.stderr,
                flush=True,
            )

    result = make_train(config, log)(jax.random.key(args.seed))
    metrics = {k: np.asarray(v) for k, v in jax.device_get(result.metrics).items()}
    wall = time.perf_counter() - start
    tail = max(1, config.generations // 10)
    info = {
        "format": "jaxais-neural/1",
        "command": command,
        "seed": args.seed,
        "config": dataclasses.asdict(config),
        "population": config.population,
        "parameters": int(sum(np.size(x) for x in jax.tree.leaves(result.params))),
        "fitness_sign": "lower is better: minus the mean episode return",
        "wall_s": round(wall, 1),
        "first_generation_s": round(first[0], 1) if first else None,
        "devices": len(jax.local_devices()),
        "final": {
            "center_fitness": float(metrics["center_fitness"][-1]),
            f"center_fitness_last_{tail}": float(metrics["center_fitness"][-tail:].mean()),
            f"center_finished_last_{tail}": float(metrics["center_finished"][-tail:].mean()),
            f"center_collisions_last_{tail}": float(metrics["center_collisions"][-tail:].mean()),
        },
        "curve": {k: [round(float(x), 4) for x in v] for k, v in metrics.items()},
        "versions": versions(),
    }
    out = Path(args.out)
    save_params(out, result.params, info)
    plot_curve(metrics, config, out / "training_curve.png")
    print(
        f"trained in {wall:.0f} s wall ({config.generations} generations of "
        f"{config.population} x {config.episodes} episodes of {config.steps} steps in "
        f"{config.world}); final centre fitness {info['final']['center_fitness']:.2f}; "
        f"wrote {out / 'params.npz'}"
    )


def plot_curve(metrics: dict[str, Any], config: TrainConfig, path: Path) -> None:
    import numpy as np
    from matplotlib.figure import Figure

    from jaxais.experiments.plotting import save_figure

    gens = np.arange(1, len(metrics["center_fitness"]) + 1)
    fig = Figure(figsize=(8, 5.5), layout="constrained")
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


# ---------------------------------------------------------------------------------- evaluation


def evaluate(args: argparse.Namespace, command: str) -> None:
    import numpy as np
    from tqdm import tqdm

    from jaxais import envs
    from jaxais.baselines.neural import NEURAL, load_params
    from jaxais.experiments import stats
    from jaxais.experiments.records import build_systems
    from jaxais.immune.network import NetworkParams
    from jaxais.trials import STL_CONFIG, run_trials, summarise

    out = Path(args.out)
    params, info = load_params(out)
    systems, seed_info = build_systems(list(REFERENCE), args.seeds, NetworkParams())
    sim = envs.default_params()
    doc: dict[str, Any] = {
        "command": command,
        "seed": args.eval_seed,
        "weights": {"config": info.get("config"), "seed": info.get("seed")},
        "ltl_seed": seed_info,
        "episode": dataclasses.asdict(STL_CONFIG),
        "versions": versions(),
        "worlds": {},
        "timings_s": {},
    }
    for name in protocol.WORLDS:
        world = envs.load_world(name)
        n = protocol.trials_for_world(name)
        t0 = time.perf_counter()
        total = n * (len(systems) + 1)  # runs (the trials go through a refilling pool)
        with tqdm(total=total, desc=f"{name}", unit="run", file=sys.stderr) as bar:
            results = run_trials(world, systems, n, args.eval_seed, STL_CONFIG, sim, bar)
            results |= run_trials(
                world, {NN_LABEL: params}, n, args.eval_seed, STL_CONFIG, sim, bar,
                controller=NEURAL,
            )  # fmt: skip
        doc["timings_s"][name] = round(time.perf_counter() - t0, 1)
        entry: dict[str, Any] = {"systems": {}, "tests": {}}
        for label, trial_set in results.items():
            entry["systems"][label] = {
                "summary": summarise(trial_set.records),
                "trials": trial_set.records,
            }
        f = {label: np.asarray([r["fitness"] for r in ts.records]) for label, ts in results.items()}
        for other in REFERENCE:
            t, p = stats.welch_t(f[NN_LABEL], f[other])
            u, p_u = stats.mann_whitney_u(f[NN_LABEL], f[other])
            entry["tests"][f"{NN_LABEL} vs {other}"] = {
                "metric": "f",
                "welch_t": t,
                "welch_p": p,
                "mann_whitney_u": u,
                "mann_whitney_p": p_u,
                "significant_99": bool(p < protocol.ALPHA),
            }
        doc["worlds"][name] = entry
        s = {k: v["summary"] for k, v in entry["systems"].items()}
        print(
            f"{name}: "
            + "; ".join(
                f"{k} f {v['fitness']:.1f} (c {v['collisions']:.2f}, tau {v['tau']:.0f} s, "
                f"failed {100 * v['failure_rate']:.0f} %)"
                for k, v in s.items()
            )
        )
    atomic_write_json(out / "evaluation.json", stats.jsonable(doc))
    atomic_write_text(out / "evaluation.md", table(doc, info))
    print(f"wrote {out / 'evaluation.json'} and {out / 'evaluation.md'}")


def _p(p: float) -> str:
    return f"{p:.2g}" if p >= 1e-4 else f"{p:.1e}"


def table(doc: dict[str, Any], info: dict[str, Any]) -> str:
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


def collect(dirs: list[str]) -> str:
    """One markdown table of several runs' evaluations (``evaluation.json`` and ``config.json``
    in each directory): mean f and failure rate per world, SIE and HDC from the first run."""
    import json

    import numpy as np

    runs = []
    for d in dirs:
        try:
            ev = json.loads((Path(d) / "evaluation.json").read_text())
            info = json.loads((Path(d) / "config.json").read_text())
        except (OSError, ValueError) as err:
            raise UserError(f"{d}: no evaluated run ({err})") from err
        runs.append((d, ev, info))
    worlds = list(runs[0][1]["worlds"])
    head = "| System | training seed | maze fitness | " + " | ".join(
        f"{w} f (failed %)" for w in worlds
    )
    lines = [head + " |", "| --- | ---: | ---: |" + " ---: |" * len(worlds)]

    def cell(trials: list[dict]) -> str:
        f = np.mean([t["fitness"] for t in trials])
        return f"{f:.1f} ({100 * np.mean([t['failed'] for t in trials]):.0f})"

    for label in REFERENCE:
        row = [cell(runs[0][1]["worlds"][w]["systems"][label]["trials"]) for w in worlds]
        lines.append(f"| {label} | – | – | " + " | ".join(row) + " |")
    pooled: dict[str, list[dict]] = {w: [] for w in worlds}
    for _, ev, info in runs:
        final = info.get("final", {})
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
        lines += _pooled_tests(runs[0][1], pooled, worlds)
    return "\n".join(lines) + "\n"


def _pooled_tests(first: dict[str, Any], pooled: dict[str, list[dict]], worlds: list[str]):
    """Rows of tests of f: every run's NN trials pooled against SIE's (from the first run)."""
    import numpy as np

    from jaxais.experiments import stats

    lines = [
        "",
        f"| World | pooled {NN_LABEL} vs SIE, mean f | median {NN_LABEL} | median SIE | "
        "Welch p | Mann-Whitney p |",
        "| --- | :---: | ---: | ---: | ---: | ---: |",
    ]
    for w in worlds:
        nn = np.asarray([t["fitness"] for t in pooled[w]])
        sie = np.asarray([t["fitness"] for t in first["worlds"][w]["systems"]["SIE"]["trials"]])
        _, p_t = stats.welch_t(nn, sie)
        _, p_u = stats.mann_whitney_u(nn, sie)
        lower = "lower" if nn.mean() < sie.mean() else "higher"
        lines.append(
            f"| {w} | {lower} | {np.median(nn):.1f} | {np.median(sie):.1f} | {_p(p_t)} | "
            f"{_p(p_u)} |"
        )
    return lines


@main_wrapper("train_baseline.py")
def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    if args.collect:
        print(collect(args.collect), end="")
        return
    for flag, value in (("--seed", args.seed), ("--eval-seed", args.eval_seed)):
        if not 0 <= value < 2**32:
            raise UserError(f"{flag} must be in [0, 2**32), got {value}")
    if args.log_every < 1:
        raise UserError(f"--log-every must be >= 1, got {args.log_every}")
    if args.eval_only and args.no_eval:
        raise UserError("--eval-only and --no-eval exclude each other")
    config = train_config(args)
    out = Path(args.out)
    if args.eval_only:
        if not (out / "params.npz").is_file():
            raise UserError(f"{out}: no params.npz to evaluate (train first)")
    else:
        check_writable_dir(out.parent)
        out.mkdir(exist_ok=True)
        check_writable_dir(out)
        if args.world not in BUILTIN_WORLDS and not Path(args.world).is_file():
            raise UserError(f"--world: no built-in world or file {args.world!r}")
    command = "train_baseline.py " + " ".join(sys.argv[1:] if argv is None else argv)

    # Imported after the flags are checked: a bad flag answers at once, without loading JAX.
    from jaxais import _speed

    _speed.setup()
    if not args.eval_only:
        train(args, config, command)
    if not args.no_eval:
        evaluate(args, command)


if __name__ == "__main__":
    run_script(main)
