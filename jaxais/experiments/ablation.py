"""What each [ours] reading does: the paper's protocol rerun with each switched to its alternative.

A :class:`Variant` switches some readings (SPEC 5-9); :func:`run_ablation` runs every system of
the protocol in every world per variant and :func:`variant_summary` scores it (claims reproduced,
mean f and failure rate). Variants differing only in traced data (readings, HDC antibodies) run as
one batch per world under tagged labels (``"SIE@hold=1"``), which get their plain label's random
streams (common random numbers); another EpisodeConfig or sim params is another call
(:func:`plan_calls`). A system identical to another variant's is run once and shared: a run's
numbers do not depend on its batch mates (``tests/test_trials.py``).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import jax
import numpy as np

from jaxais import envs
from jaxais import trials as trials_module
from jaxais.controllers import System
from jaxais.envs.struct import device_array
from jaxais.experiments import claims, protocol, stats
from jaxais.immune.network import NetworkParams
from jaxais.immune.readings import ALPHA_ON_SELF, HOLD, SIGMA0_FLOOR, Readings
from jaxais.immune.readings import readings as make_readings
from jaxais.io import (
    RUN_BYTES,
    Run,
    atomic_write_json,
    atomic_write_text,
    check_memory,
    check_names,
    check_path,
    open_run,
    read_json_object,
)
from jaxais.lock import scoped
from jaxais.loop import EpisodeConfig
from jaxais.seed import Seed
from jaxais.systems import HAND_DESIGNED, hand_designed_sets, make_system, parse_label
from jaxais.trials import STL_CONFIG, TrialSet

__all__ = [
    "VARIANTS", "Ablation", "Variant", "ablate", "document", "markdown",
    "plan_calls", "run_ablation", "select", "variant_systems",
]  # fmt: skip

REPORTED = ("SIE", "HDC", "UIE-R1", "URL-R1")  # the systems the table shows

# The earlier HDC: "target seen" tracks markers (SPEC 8: the paper's HDC does not track).
TRACKING_HDC = [
    {"antigen": "target seen", "type": "track markers", "S": 350, "A": 30}
    if item["antigen"] == "target seen"
    else item
    for item in HAND_DESIGNED
]


@dataclasses.dataclass(frozen=True)
class Variant:
    """A setting of the [ours] readings (defaults: ours); ``name`` also tags labels in a batch."""

    name: str
    description: str  # one line: what is switched, and to what
    hold: int = HOLD  # iterations a selected behaviour acts [ours: 31; literal 1]
    count_encounters: bool = True  # obstacle penalty counts encounters [ours], else iterations
    sigma0_floor: float = SIGMA0_FLOOR  # floor on eq (4)'s initial column means [ours: 0.05]
    collision_rule: str = "episode"  # [ours], or "entry": every entry into a collision antigen
    stop_at_collision_cap: bool = False  # the earlier reading: a run ends at the cap
    hdc_tracks: bool = False  # the earlier HDC: tracks the target when it sees it
    ir_noise: bool = True  # False: noise-free IR (a world's own extra noise stays)
    alpha_on_self: bool = ALPHA_ON_SELF  # eqs (7)-(8) also sum alpha's own set (earlier reading)
    swap_penalties: bool = False  # not a reading: shows what the paper's 1.0/0.5 do to UIE, URL

    def readings(self) -> Readings:
        """The controllers' readings of this variant."""
        return make_readings(
            hold=self.hold,
            count_encounters=self.count_encounters,
            sigma0_floor=self.sigma0_floor,
            alpha_on_self=self.alpha_on_self,
        )

    def network(self) -> NetworkParams:
        """The network constants: the paper's, penalties swapped if set."""
        net = NetworkParams()
        if not self.swap_penalties:
            return net
        return net.replace(
            penalty_idiotypic=net.penalty_non_idiotypic,
            penalty_non_idiotypic=net.penalty_idiotypic,
        )

    def config(self, base: EpisodeConfig = STL_CONFIG) -> EpisodeConfig:
        """``base`` (caps, recording) with this variant's collision rule and stopping rule."""
        return dataclasses.replace(
            base,
            collision_rule=self.collision_rule,
            stop_at_collision_cap=self.stop_at_collision_cap,
        )

    def sim_params(self) -> envs.SimParams:
        """The simulator parameters: the defaults, with the IR noise table zeroed if off."""
        if self.ir_noise:
            return envs.default_params()
        return envs.default_params(ir_noise=np.zeros(10, np.float32))

    def settings(self) -> dict[str, Any]:
        """Every setting, as plain JSON."""
        return {
            f.name: getattr(self, f.name)
            for f in dataclasses.fields(self)
            if f.name not in ("name", "description")
        }

    def switched(self) -> list[str]:
        """The settings that differ from ours."""
        ours = Variant("", "").settings()
        return [k for k, v in self.settings().items() if v != ours[k]]


VARIANTS = (
    Variant("ours", "all our readings (the defaults)"),
    Variant("hold=1", "a selected behaviour acts for one 32 ms iteration, not about 1 s", hold=1),
    Variant(
        "count_encounters=False",
        "the 15-obstacle-encounter penalty counts consecutive iterations, not encounters",
        count_encounters=False,
    ),
    Variant(
        "sigma0_floor=0",
        "eq (4) literal: a column whose initial mean is 0 stays pinned at 0",
        sigma0_floor=0.0,
    ),
    Variant(
        "collision_rule=entry",
        "every entry into a collision antigen counts, not one per contact episode",
        collision_rule="entry",
    ),
    Variant(
        "stop_at_collision_cap=True",
        "a run stops at 100 collisions",
        stop_at_collision_cap=True,
    ),
    Variant("hdc_tracks=True", "the HDC tracks the target when it sees it", hdc_tracks=True),
    Variant(
        "ir_noise=0",
        "noise-free IR: the simulator's IR noise table off (the real world keeps its own noise)",
        ir_noise=False,
    ),
    Variant(
        "alpha_on_self=True",
        "eqs (7)-(8) also sum alpha's effect on its own set (the engine's earlier reading; "
        "section 4.3 has alpha act on the others)",
        alpha_on_self=True,
    ),
    Variant(
        "penalties=swapped",
        "the paper's penalties swapped: 1.0 removed from an idiotypic robot's antibody, 0.5 "
        "from an RL-only robot's (not a reading: shows what the paper's rule does to UIE, URL)",
        swap_penalties=True,
    ),
    Variant(
        "literal",
        "every old reading together: hold=1, count_encounters=False, sigma0_floor=0, "
        "collision_rule=entry, stop_at_collision_cap=True, hdc_tracks=True",
        hold=1,
        count_encounters=False,
        sigma0_floor=0.0,
        collision_rule="entry",
        stop_at_collision_cap=True,
        hdc_tracks=True,
    ),
)


def select(names: Sequence[str] | None) -> tuple[Variant, ...]:
    """The variants named, in :data:`VARIANTS`' order (all for None); ValueError if unknown."""
    if names is None:
        return VARIANTS
    known = {v.name: v for v in VARIANTS}
    unknown = [n for n in names if n not in known]
    if unknown:
        raise ValueError(f"unknown variant(s) {unknown} (choose from {', '.join(known)})")
    if not names:
        raise ValueError("no variant named")
    if len(set(names)) != len(names):
        raise ValueError(f"a variant is named twice in {list(names)}")
    return tuple(v for v in VARIANTS if v.name in names)


def variant_systems(
    variant: Variant, labels: Sequence[str], seed: Seed | None
) -> dict[str, System]:
    """The systems of ``labels`` (e.g. ``"UIE-R2"``) as ``variant`` builds them."""
    out = {}
    for name in labels:
        system = make_system(name, seed, network=variant.network(), readings=variant.readings())
        if variant.hdc_tracks and parse_label(name)[0] == "HDC":
            antibodies, _ = hand_designed_sets(system.paratopes.shape[0], TRACKING_HDC)
            system = system.replace(antibodies=jax.tree.map(device_array, antibodies))
        out[name] = system
    return out


def _same(a: Any, b: Any) -> bool:
    """Two pytrees with the same structure and equal leaves."""
    la, ta = jax.tree.flatten(a)
    lb, tb = jax.tree.flatten(b)
    return ta == tb and all(
        np.shape(x) == np.shape(y) and np.array_equal(np.asarray(x), np.asarray(y))
        for x, y in zip(la, lb, strict=True)
    )


@dataclasses.dataclass(frozen=True)
class Call:
    """One batch: the variants (names) sharing an episode config (static) and sim params."""

    config: EpisodeConfig
    ir_noise: bool
    variants: tuple[str, ...]


def plan_calls(variants: Sequence[Variant], base: EpisodeConfig = STL_CONFIG) -> list[Call]:
    """Group the variants into batches: one per (episode config, simulator parameters)."""
    groups: dict[tuple[EpisodeConfig, bool], list[str]] = {}
    for v in variants:
        groups.setdefault((v.config(base), v.ir_noise), []).append(v.name)
    return [Call(cfg, noise, tuple(names)) for (cfg, noise), names in groups.items()]


def batch_systems(
    names: Sequence[str], systems: Mapping[str, Mapping[str, System]], share: bool = True
) -> tuple[dict[str, System], dict[str, dict[str, str]]]:
    """One call's batch, ``systems`` being variant -> label -> System.

    Returns (tagged label ``"SIE@hold=1"`` -> System, variant -> label -> the tagged label whose
    trials it gets); with ``share`` a system equal to an earlier variant's is run once.
    """
    batch: dict[str, System] = {}
    source: dict[str, dict[str, str]] = {name: {} for name in names}
    for i, name in enumerate(names):
        for label, system in systems[name].items():
            same = (e for e in names[:i] if share and _same(systems[e][label], system))
            twin = next((source[e][label] for e in same), None)
            if twin is None:
                twin = f"{label}@{name}"
                batch[twin] = system
            source[name][label] = twin
    return batch, source


@dataclasses.dataclass
class Ablation:
    """The trials of an ablation, and one log dict per batch run (``run.json``'s calls)."""

    trials: dict[str, dict[str, dict[str, TrialSet]]]  # variant -> world -> label -> trials
    calls: list[dict[str, Any]]

    def records(self, variant: str) -> dict[str, dict[str, list[dict[str, Any]]]]:
        """``{world: {label: [trial record]}}`` of a variant (what ``claims`` reads)."""
        return {
            world: {label: ts.records for label, ts in by_label.items()}
            for world, by_label in self.trials[variant].items()
        }


def run_ablation(
    worlds: Sequence[str],
    variants: Sequence[Variant],
    seed: int,
    ltl_seed: Seed | None,
    n_trials: int | Mapping[str, int],
    base: EpisodeConfig = STL_CONFIG,
    share: bool = True,
    progress: Any = None,
    folder: Run | None = None,
) -> Ablation:
    """Run every variant's protocol: per world, one :func:`~jaxais.trials.run_trials` per call.

    Args:
        n_trials: trials per system (or per world name).
        base: the episode config's caps and recording; each variant sets its own rules.
        progress: optional tqdm bar, advanced in runs ended (iterations with ``base.record``);
            its total is set first.
        folder: each batch's records are a unit there (``batches/I.json``); a held one is read.
    """
    by_name = {v.name: v for v in variants}
    sim = {call: by_name[call.variants[0]].sim_params() for call in plan_calls(variants, base)}
    out: dict[str, dict[str, dict[str, TrialSet]]] = {v.name: {} for v in variants}
    log: list[dict[str, Any]] = []
    plan = []  # every batch first, so the bar knows its total
    for world_name in worlds:
        world = envs.load_world(world_name)
        world_labels = protocol.systems_for_world(world_name)
        n = n_trials if isinstance(n_trials, int) else n_trials[world_name]
        systems = {v.name: variant_systems(v, world_labels, ltl_seed) for v in variants}
        for call, sim_params in sim.items():
            batch, source = batch_systems(call.variants, systems, share)
            # The progress a batch makes: its runs, or its iterations when it keeps poses.
            units = len(batch) * n
            if call.config.record:
                units = call.config.max_iterations(sim_params.dt)
            plan.append((world_name, world, n, call, batch, source, units))
    if progress is not None:
        progress.reset(total=sum(p[-1] for p in plan))
    for i, (world_name, world, n, call, batch, source, units) in enumerate(plan):
        if progress is not None:
            before = progress.n
            progress.set_description_str(
                f"{world_name}: {', '.join(call.variants)} ({len(batch)} systems x {n})"
            )
        timings: dict[str, float] = {}
        unit = f"batch {i}"  # its records in batches/, written whole before the manifest names it
        if folder is not None and unit in folder.units:
            timings = folder.units[unit]
            records = read_json_object(folder.out / "batches" / f"{i}.json")
            results = {label: TrialSet(recs, None) for label, recs in records.items()}
        else:
            results = trials_module.run_trials(
                world, batch, n, seed, call.config, sim[call], progress, timings
            )
            if folder is not None and folder.write:
                (folder.out / "batches").mkdir(exist_ok=True)
                records = {label: ts.records for label, ts in results.items()}
                atomic_write_json(folder.out / "batches" / f"{i}.json", records)
                folder.finish(unit, timings)
        if progress is not None:  # a batch that ended early completes its share
            progress.update(max(0, units - (progress.n - before)))
        for name in call.variants:
            out[name][world_name] = {
                label: results[tagged] for label, tagged in source[name].items()
            }
        log.append(
            {
                "world": world_name,
                "variants": list(call.variants),
                "episode": {
                    "collision_rule": call.config.collision_rule,
                    "stop_at_collision_cap": call.config.stop_at_collision_cap,
                },
                "ir_noise": call.ir_noise,
                "systems": list(batch),
                "shared": {
                    name: {lab: t for lab, t in src.items() if t != f"{lab}@{name}"}
                    for name, src in source.items()
                    if any(t != f"{lab}@{name}" for lab, t in src.items())
                },
                "runs": len(batch) * n,
                "run_s": timings.get("compile_s", 0.0) + timings.get("run_s", 0.0),
            }
        )
    return Ablation(out, log)


def _reported(records: Sequence[Mapping[str, Any]]) -> dict[str, float]:
    return {
        "f": float(stats.metric_values(records, "f").mean()),
        "failure_rate": float(np.mean([bool(r["failed"]) for r in records])),
        "trapped_s": float(np.mean([r["trapped_s"] for r in records])),
        "locked_s": float(np.mean([r.get("locked_s", np.nan) for r in records])),
        "replaced": float(np.mean([r.get("replaced") or 0 for r in records])),
    }


def variant_summary(results_by_world: Mapping[str, Mapping[str, Sequence[Mapping]]]) -> dict:
    """A variant's claims summary, held claim ids, and :data:`REPORTED` systems' means per world."""
    ledger = claims.claims(results_by_world)
    return {
        "claims": claims.summary(ledger),
        "held": [c["id"] for c in ledger if c["held"] is True],
        "worlds": {
            world: {
                label: _reported(by_label[label])
                for label in REPORTED
                if len(by_label.get(label, ())) > 0
            }
            for world, by_label in results_by_world.items()
        },
    }


def document(
    ablation: Ablation, variants: Sequence[Variant], n_trials: Mapping[str, int]
) -> dict[str, Any]:
    """The ``ablation.json`` document: per variant its settings and :func:`variant_summary`."""
    return stats.jsonable(
        {
            "reported_systems": list(REPORTED),
            "trials": dict(n_trials),
            "variants": [
                {
                    "name": v.name,
                    "description": v.description,
                    "settings": v.settings(),
                    "switched": v.switched(),
                    **variant_summary(ablation.records(v.name)),
                }
                for v in variants
            ],
        }
    )


def _cell(value: float | None, fmt: str) -> str:
    return "–" if value is None else format(value, fmt)


def markdown(doc: Mapping[str, Any]) -> str:
    """The ablation table (claims, f per world and system, SIE fail %), notes, penalty table."""
    worlds = list(doc["trials"])
    reported = doc.get("reported_systems", REPORTED)
    head = ["variant", "claims reproduced"]
    for w in worlds:
        head += [f"{w} {label} f" for label in reported] + [f"{w} SIE fail %"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for v in doc["variants"]:
        c = v["claims"]
        row = [f"`{v['name']}`", f"{c['reproduced']} of {c['evaluated']}"]
        for w in worlds:
            by = v["worlds"].get(w, {})
            row += [_cell(by.get(label, {}).get("f"), ".0f") for label in reported]
            fail = by.get("SIE", {}).get("failure_rate")
            row.append(_cell(None if fail is None else 100 * fail, ".0f"))
        lines.append("| " + " | ".join(row) + " |")
    trials = ", ".join(f"{w} {n}" for w, n in doc["trials"].items())
    notes = [
        "",
        f"Trials per system: {trials}. f = (8c + τ)/2 (s, lower is better), c capped at 100. "
        "Claims: of the paper's claims that our results can evaluate "
        "(`jaxais.experiments.claims`).",
        "",
    ]
    notes += [f"- `{v['name']}`: {v['description']}." for v in doc["variants"]]
    return "\n".join(lines + notes + _penalty_table(doc, worlds)) + "\n"


def _penalty_table(doc: Mapping[str, Any], worlds: Sequence[str]) -> list[str]:
    """UIE-R1 against URL-R1 under ours and the swapped penalties: f, replacements, trapped."""
    rows = [v for v in doc["variants"] if v["name"] in ("ours", "penalties=swapped")]
    if len(rows) < 2:
        return []
    lines = [
        "",
        "UIE-R1 against URL-R1, with the paper's penalties (`ours`) and swapped: mean f / "
        "antibodies replaced per run / trapped time (s).",
        "",
        "| variant | world | UIE-R1 | URL-R1 |",
        "|---|---|---|---|",
    ]
    for v in rows:
        for w in worlds:
            by = v["worlds"].get(w, {})
            cells = [
                " / ".join(
                    _cell(by.get(label, {}).get(key), fmt)
                    for key, fmt in (("f", ".0f"), ("replaced", ".1f"), ("trapped_s", ".0f"))
                )
                for label in ("UIE-R1", "URL-R1")
            ]
            lines.append(f"| `{v['name']}` | {w} | {cells[0]} | {cells[1]} |")
    return lines


def figure(doc: Mapping[str, Any]) -> Any:
    """Claims reproduced per variant, and SIE's mean f per world and variant (a Figure)."""
    from jaxais.experiments.plotting import new_figure

    variants = doc["variants"]
    names = [v["name"] for v in variants]
    worlds = list(doc["trials"])
    fig = new_figure((12, 0.45 * len(names) + 2.0))
    ax_c, ax_f = fig.subplots(1, 2, sharey=True)
    y = np.arange(len(names))
    held = [v["claims"]["reproduced"] for v in variants]
    evaluated = [v["claims"]["evaluated"] for v in variants]
    ax_c.barh(y, evaluated, color="0.85", label="evaluated")
    ax_c.barh(y, held, color="tab:blue", label="reproduced")
    for yi, h, e in zip(y, held, evaluated, strict=True):
        ax_c.text(h + 0.3, yi, f"{h}/{e}", va="center", fontsize=8)
    ax_c.set_yticks(y, names)
    ax_c.invert_yaxis()
    ax_c.set_xlabel("paper's claims")
    ax_c.set_title("claims reproduced")
    ax_c.legend(loc="lower right", fontsize=8)
    height = 0.8 / max(1, len(worlds))
    for k, w in enumerate(worlds):
        f = [v["worlds"].get(w, {}).get("SIE", {}).get("f", np.nan) for v in variants]
        ax_f.barh(y - 0.4 + (k + 0.5) * height, f, height, label=w)
    ax_f.set_xlabel("SIE mean f = (8c + τ)/2 (lower is better)")
    ax_f.set_title("SIE's fitness per world")
    ax_f.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)  # clear of the bars
    return fig


@scoped  # its folder's lock goes when it returns or raises
def ablate(
    out: str | Path,
    *,
    worlds: str | Sequence[str] = protocol.WORLDS,
    variants: str | Sequence[str] | None = None,
    trials: int | None = None,
    seed: int = 0,
    seeds: str | Path | None = None,
    tau_cap: float = protocol.TAU_CAP,
    collision_cap: int = protocol.COLLISION_CAP,
    share: bool = True,
    resume: bool = False,
) -> tuple[dict[str, Any], dict[str, Any]]:
    """Run the ablation and write ablation.json/.md/.png and run.json into ``out`` (missing or
    empty; ``resume`` finishes an interrupted run); ``worlds`` and ``variants`` are lists of
    names or comma-separated strings. Returns (ablation.json, run.json) documents;
    ValueError (one line) on a bad argument, before anything runs.
    """
    import os
    import sys
    import time

    from tqdm.auto import tqdm

    from jaxais.experiments.one_system import check_types, command_line
    from jaxais.experiments.plotting import save_figure
    from jaxais.experiments.records import load_ltl_seed, versions

    check_path(out, "--out", "a folder's path")
    check_types(trials=trials, seed=seed, seeds=seeds, share=share, resume=resume)
    worlds = protocol.check_worlds(worlds)
    if variants is not None:  # "ours,hold=1" is two
        variants = check_names(variants, "--variants")
    protocol.check_seed(seed)
    if trials is not None and trials < 2:
        raise ValueError(f"--trials must be >= 2 (t-tests need two per group), got {trials}")
    tau_cap, collision_cap = protocol.check_caps(tau_cap, collision_cap)
    try:
        chosen = select(variants)
    except ValueError as err:
        raise ValueError(f"--variants: {err}") from None
    if trials is not None:  # every run's record is kept to the end
        runs = len(chosen) * sum(len(protocol.systems_for_world(w)) for w in worlds)
        check_memory(trials, runs * RUN_BYTES, "--trials")
    settings = dict(worlds=worlds, variants=[v.name for v in chosen], trials=trials, seed=seed,
                    seeds=None if seeds is None else str(seeds), tau_cap=tau_cap,
                    collision_cap=collision_cap, share=share)  # fmt: skip
    started = time.perf_counter()
    # Read once, and early: a missing or corrupt seed fails before anything is written.
    ltl_seed, seed_info = load_ltl_seed(seeds)
    folder = open_run(out, "ablate", settings, resume=resume)
    out = folder.out
    base = dataclasses.replace(STL_CONFIG, tau_cap=tau_cap, collision_cap=collision_cap)
    n_trials = {w: protocol.trials_for_world(w) if trials is None else trials for w in worlds}
    with tqdm(unit="run", file=sys.stderr, desc="ablation") as bar:  # run_ablation sets the total
        result = run_ablation(
            worlds, chosen, seed, ltl_seed, n_trials, base, share=share, progress=bar,
            folder=folder,
        )  # fmt: skip
    wall = time.perf_counter() - started

    doc = document(result, chosen, n_trials)
    atomic_write_json(out / "ablation.json", doc)
    atomic_write_text(out / "ablation.md", "# Ablation of our readings\n\n" + markdown(doc))
    save_figure(figure(doc), out / "ablation.png")
    # The command that regenerates the run, every flag explicit, without the output directory.
    flags = {"--out": "DIR", "--worlds": ",".join(worlds),
             "--variants": ",".join(settings["variants"]), "--seed": seed, "--tau-cap": tau_cap,
             "--collision-cap": collision_cap, "--trials": trials,
             "--seeds": None if seeds is None else seed_info["path"],
             "--no-share": not share}  # fmt: skip
    run = {
        "command": command_line("ablate.py", flags),
        "seed": seed,
        "trials": n_trials,
        "worlds": worlds,
        "variants": [v.name for v in chosen],
        "episode": {"tau_cap": base.tau_cap, "collision_cap": base.collision_cap},
        "share_identical_systems": share,
        "ltl_seed": seed_info,
        "versions": versions(),
        "cpu_cores": os.cpu_count(),
        "calls": result.calls,
        "timings_s": {"total_s": wall, "run_s": sum(c["run_s"] for c in result.calls)},
    }
    atomic_write_json(out / "run.json", run)
    folder.complete()
    return doc, run
