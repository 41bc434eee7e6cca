"""How robust each of the paper's claims is to what the paper left unsaid: a map over LTL seeds x
world scales x collision counting rules.

For each LTL seed s (the seeds ledger's: ``LTL/seed_s``, evolved by the ledger's own code,
:func:`seeds.evolve`, only where missing) and world scale K, :func:`run` runs as a subprocess
``jaxais.scripts.reproduce --seeds LTL/seed_s/seed --out OUT/stl/seed_s_scale_K --seed s
--no-baseline --world-scale K``; its claims.json holds the claims under every counting rule
(the rules cost no extra runs), so each (s, K) gives a cell per rule. OUT/robustness.json
(:data:`FORMAT`), robustness.md and robustness.png are rebuilt after every (s, K); OUT/manifest.json
records the finished ones (``resume``). Nothing here imports JAX: the subprocesses have the device.
"""

from __future__ import annotations

import functools
import math
import os
import shutil
import sys
import threading
import time
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

from jaxais import io
from jaxais.experiments import protocol, seeds
from jaxais.io import MANIFEST, atomic_write_json, atomic_write_text, open_run

__all__ = ["FORMAT", "ROBUST", "classify", "markdown", "run", "summarise"]

FORMAT = "jaxais-robustness/1"
ROBUST = 0.8
"""A claim holding in at least this fraction of the cells is robust; in none, never."""
SCALES = (1.0, 2.0)
"""The default world scales: ours [ours: 1] and twice it (the audit's)."""
AXES = ("ltl_seed", "scale", "rule")
DEFAULTS = {"scale": 1.0, "rule": protocol.DEFAULT_RULE}
"""The choices' defaults (the seed has none: every LTL seed is a draw)."""


def _unit(s: int, scale: float) -> str:
    return f"seed {s} scale {scale:g}"


def _stl(out: Path, s: int, scale: float) -> Path:
    return out / "stl" / f"seed_{s}_scale_{scale:g}"


def cells_of(claims_doc: Mapping[str, Any], s: int, scale: float, rules: Sequence[str]):
    """The cells of one reproduce.py run (its ``claims.json``), one per counting rule in
    ``rules`` (ValueError when the run lacks one: records made before c was counted per rule)."""
    ledgers = {protocol.DEFAULT_RULE: claims_doc} | dict(claims_doc.get("by_rule", {}))
    out = []
    for rule in rules:
        if rule not in ledgers:
            raise ValueError(f"seed {s}, scale {scale:g}: its claims.json has no {rule!r} rule")
        held = {c["id"]: c["held"] for c in ledgers[rule]["claims"]}
        out.append({"ltl_seed": s, "trial_seed": s, "scale": scale, "rule": rule, "claims": held})
    return out


def classify(fraction: float | None) -> str:
    """ "robust" (>= :data:`ROBUST`), "never" (0 or no cell evaluated it) or "fragile"."""
    if not fraction:
        return "never"
    return "robust" if fraction >= ROBUST else "fragile"


def _fraction(cells: Iterable[Mapping[str, Any]], cid: str) -> float | None:
    """Of the cells that evaluated ``cid``, the fraction where it holds (None: none did)."""
    held = [c["claims"].get(cid) for c in cells]
    held = [h for h in held if h is not None]
    return sum(held) / len(held) if held else None


def summarise(
    cells: Sequence[Mapping[str, Any]], requested: Mapping[str, Sequence[Any]]
) -> dict[str, Any]:
    """``robustness.json`` of ``cells``: per claim its fraction of cells, its marginals (per
    value of one axis, the fraction over the cells with the other choices at their defaults,
    :data:`DEFAULTS`) and its class (:func:`classify`); the counts of each class."""
    ids = list(dict.fromkeys(cid for c in cells for cid in c["claims"]))
    claims = {}
    for cid in ids:
        fraction = _fraction(cells, cid)
        marginals = {}
        for axis in AXES:
            others = {k: v for k, v in DEFAULTS.items() if k != axis}
            at = [c for c in cells if all(c[k] == v for k, v in others.items())]
            values = list(dict.fromkeys(c[axis] for c in at))
            marginals[axis] = {
                f"{v:g}" if isinstance(v, float) else str(v): _fraction(
                    [c for c in at if c[axis] == v], cid
                )
                for v in values
            }
        claims[cid] = {"fraction": fraction, "class": classify(fraction), "marginals": marginals}
    classes = {k: sum(c["class"] == k for c in claims.values()) for k in ("robust", "fragile")}
    classes["never"] = len(claims) - sum(classes.values())
    want = math.prod(len(v) for v in requested.values())
    return {
        "format": FORMAT,
        "axes": {k: list(v) for k, v in requested.items()},
        "robust_at": ROBUST,
        "classes": classes,
        "claims": claims,
        "cells": list(cells),
        "complete": len(cells) >= want,
        "done": len(cells),
        "requested": want,
    }


def headline(doc: Mapping[str, Any]) -> str:
    """One line: the classes' counts over the cells done."""
    k = doc["classes"]
    return (
        f"{k['robust']} robust, {k['fragile']} fragile, {k['never']} never of "
        f"{len(doc['claims'])} claims over {doc['done']} of {doc['requested']} cells"
    )


def markdown(doc: Mapping[str, Any]) -> str:
    """``robustness.md``: the classes, then each claim with its fraction and marginals."""
    axes = doc["axes"]
    status = "complete" if doc["complete"] else "partial: run it again with --resume"
    lines = [
        "# How robust each claim is to what the paper left unsaid",
        "",
        f"{doc['done']} of {doc['requested']} cells done ({status}): LTL seeds "
        f"{', '.join(map(str, axes['ltl_seed']))} x world scales "
        f"{', '.join(f'{k:g}' for k in axes['scale'])} x collision counting "
        f"{', '.join(axes['rule'])} (per contact episode, ours; per reading of Vm >= 2400).",
        "",
    ]
    if any(k != 1 for k in axes["scale"]):
        lines += [
            "The world scale applies to worlds 1 and 2; the real pen keeps its size (the paper "
            "gives it), so a real/ claim's cells at another scale repeat its cells at ours.",
            "",
        ]
    lines += [
        f"**{headline(doc)}** (robust: holds in >= {100 * doc['robust_at']:.0f} % of the cells; "
        "never: in none).",
        "",
        "Marginals: the fraction over one axis's values with the other choices at ours (scale "
        "1, c per contact episode), over every seed.",
        "",
    ]
    head = ["claim", "class", "cells held"]
    head += [f"scale {k:g}" for k in axes["scale"]] + [f"c per {r}" for r in axes["rule"]]
    lines += ["| " + " | ".join(head) + " |", "|---|---|" + "---:|" * (len(head) - 2)]
    pct = lambda x: "–" if x is None else f"{100 * x:.0f} %"
    ranked = sorted(doc["claims"].items(), key=lambda kv: -(kv[1]["fraction"] or 0.0))
    for cid, c in ranked:
        m = c["marginals"]
        row = [cid, c["class"], pct(c["fraction"])]
        row += [pct(m["scale"].get(f"{k:g}")) for k in axes["scale"]]
        row += [pct(m["rule"].get(r)) for r in axes["rule"]]
        lines.append("| " + " | ".join(row) + " |")
    if doc.get("command"):
        lines += ["", "## How it was made", "", f"`{doc['command']}`"]
    return "\n".join(lines) + "\n"


def figure(doc: Mapping[str, Any], path: Path) -> None:
    """A heat map, claims x cells (held, not held, not evaluated)."""
    import numpy as np

    from jaxais.experiments.plotting import new_figure, save_figure

    cells, ids = doc["cells"], list(doc["claims"])
    if not cells or not ids:
        return
    value = {True: 1.0, False: 0.0, None: np.nan}
    grid = np.array([[value[c["claims"].get(cid)] for c in cells] for cid in ids])
    fig = new_figure((max(6.0, 0.25 * len(cells) + 3.5), 0.22 * len(ids) + 1.8))
    ax = fig.subplots()
    ax.imshow(grid, aspect="auto", cmap="RdYlGn", vmin=0.0, vmax=1.0, interpolation="nearest")
    labels = [f"s{c['ltl_seed']} x{c['scale']:g} {c['rule'][:3]}" for c in cells]
    ax.set_xticks(range(len(cells)), labels, rotation=90, fontsize=6)
    ax.set_yticks(range(len(ids)), ids, fontsize=6)
    ax.set_title("claims held (green) per cell: LTL seed, world scale, c counted per ...")
    save_figure(fig, path, dpi=110)


def _check(seeds_: list[int], scales: list[float], rules: list[str], trials, jobs) -> None:
    if not seeds_ or len(set(seeds_)) != len(seeds_):
        raise ValueError(f"--seeds must be distinct and at least one, got {seeds_}")
    if any(isinstance(s, bool) or not isinstance(s, int) or not 0 <= s <= seeds.MAX_SEED
           for s in seeds_):  # fmt: skip
        raise ValueError(f"--seeds must be integers in [0, {seeds.MAX_SEED}], got {seeds_}")
    for k in scales:
        protocol.check_world_scale(k, flag="--scales")
    if not scales or len(set(scales)) != len(scales):
        raise ValueError(f"--scales must be distinct and at least one, got {scales}")
    bad = [r for r in rules if r not in protocol.COUNTING_RULES]
    if bad or not rules or len(set(rules)) != len(rules):
        raise ValueError(
            f"--rules: one or more of {', '.join(protocol.COUNTING_RULES)}, each once, got {rules}"
        )
    if trials is not None and (isinstance(trials, bool) or not isinstance(trials, int)
                               or trials < 2):  # fmt: skip
        raise ValueError(f"--trials must be an integer >= 2 (t-tests need two), got {trials!r}")
    if isinstance(jobs, bool) or not isinstance(jobs, int) or jobs < 1:
        raise ValueError(f"--jobs must be an integer >= 1, got {jobs!r}")


def _children_cpu() -> float:
    """CPU seconds (user + system) of every child process waited for so far."""
    t = os.times()
    return t.children_user + t.children_system


def run(
    out: str | Path,
    seeds_: Iterable[int] = range(10),
    scales: Sequence[float] = SCALES,
    rules: Sequence[str] = protocol.COUNTING_RULES,
    trials: int | None = None,
    jobs: int | None = None,
    ltl: str | Path | None = None,
    extra_args: Sequence[str] = (),
    progress: bool = True,
    *,
    command: str | None = None,
    runner: seeds.Runner | None = None,
    resume: bool = False,
) -> dict[str, Any]:
    """The robustness map in ``out``: every (LTL seed, world scale) unless done, then its cells
    under each of ``rules``; returns ``robustness.json``.

    Args:
        seeds_: the LTL seeds (each also the trials' seed, as in the seeds ledger).
        ltl: the folder of the ledger's LTL runs (``ltl/seed_s``; default ``out/ltl``); a seed
            missing there is evolved with the ledger's code.
        trials: reproduce.py's ``--trials`` (default: the paper's counts).
        jobs: (seed, scale) runs side by side (default: one per core); their logs go to
            ``out/logs`` when above 1.
        extra_args: further reproduce.py flags (``--tau-cap``, ...).
        runner: runs one subprocess (tests inject one).

    Raises:
        ValueError: a bad argument, or ``out`` holding another run (or none to resume).
        seeds.SeedRunError: a subprocess failed (the running units finish and are kept).
    """
    out, seeds_ = Path(out), list(seeds_)
    scales, rules = [float(k) for k in scales], list(rules)
    jobs = seeds.default_jobs() if jobs is None else jobs
    _check(seeds_, scales, rules, trials, jobs)
    extra = [str(a) for a in extra_args]
    reserved = (*seeds.RESERVED, "--world-scale")
    if any(a.split("=")[0] in reserved for a in extra):
        raise ValueError(f"extra_args may not set {', '.join(reserved)} (the map sets them)")
    if trials is not None:
        runs = max(len(protocol.systems_for_world(w)) for w in protocol.WORLDS) + 2
        io.check_memory(trials, min(jobs, len(seeds_) * len(scales)) * runs * io.RUN_BYTES,
                        "--trials")  # fmt: skip
    ltl_root = out / "ltl" if ltl is None else Path(ltl)
    settings = {"seeds": seeds_, "scales": scales, "rules": rules, "trials": trials,
                "extra_args": extra, "ltl": None if ltl is None else str(ltl)}  # fmt: skip
    if command is None:
        command = f"robustness.run({str(out)!r}, seeds_={seeds_}, scales={scales}, rules={rules})"
    folder = open_run(out, "robustness", settings, resume=resume)
    lock, stop = threading.Lock(), threading.Event()
    procs = seeds._Processes()
    launch = runner or procs
    seed_locks = {s: threading.Lock() for s in seeds_}  # one LTL per seed, whatever its scales
    started, cpu0 = time.perf_counter(), _children_cpu()
    before = dict(folder.units.get("_session", {}) or {})

    def note(text: str) -> None:
        if progress:
            print(text, file=sys.stderr, flush=True)

    def log(name: str) -> Path | None:
        return out / "logs" / f"{name}.log" if jobs > 1 else None

    def write() -> dict[str, Any]:
        with lock:
            cells = []
            for s in seeds_:
                for k in scales:
                    if _unit(s, k) in folder.units:
                        doc = seeds._read_json(_stl(out, s, k) / "claims.json")
                        cells += cells_of(doc, s, k, rules)
            axes = {"ltl_seed": seeds_, "scale": scales, "rule": rules}
            doc = summarise(cells, axes) | {"command": command}
            atomic_write_json(out / "robustness.json", doc)
            atomic_write_text(out / "robustness.md", markdown(doc))
            figure(doc, out / "robustness.png")
            wall = {u: v["wall_s"] for u, v in folder.units.items() if u != "_session"}
            run_doc = {"command": command, **settings, "jobs": jobs,
                       "versions": seeds._versions(out / "_", ()),
                       "wall_s_total": before.get("wall_s", 0.0) + time.perf_counter() - started,
                       "cpu_s_total": before.get("cpu_s", 0.0) + _children_cpu() - cpu0,
                       "wall_s": wall}  # fmt: skip
            run_doc["cpu_hours"] = run_doc["cpu_s_total"] / 3600.0
            atomic_write_json(out / "run.json", run_doc)
            return doc

    def failed_for(s: int):
        def failed(stage: str, script: str, code: int) -> seeds.SeedRunError:
            return seeds.SeedRunError(
                f"seed {s}: the {stage} ({script}) failed, exit status {code}"
            )

        return failed

    def unit(s: int, k: float) -> None:
        name = _unit(s, k)
        try:
            if stop.is_set() or name in folder.units:
                return
            ltl_dir = ltl_root / f"seed_{s}"
            with seed_locks[s]:
                seeds.evolve(ltl_dir, s, launch, log(f"seed_{s}.ltl"), note, failed_for(s))
            if stop.is_set():
                return
            stl = _stl(out, s, k)
            again = (stl / MANIFEST).is_file()  # reproduce.py began: it finishes its own run
            if stl.exists() and not again:
                shutil.rmtree(stl)
            cmd = [
                sys.executable,
                "-m",
                "jaxais.scripts.reproduce",
                "--seeds",
                str(ltl_dir / "seed"),
                "--out",
                str(stl),
                "--seed",
                str(s),
                "--no-baseline",
            ]
            cmd += ["--world-scale", f"{k:g}"] * (k != 1)
            cmd += ["--trials", str(trials)] * (trials is not None)
            cmd += ["--resume"] * again  # fmt: skip
            note(f"{name}: STL {'resumed' if again else 'started'} ({stl})")
            t = time.perf_counter()
            code = launch(cmd + extra, log(f"seed_{s}_scale_{k:g}.stl"))
            if code != 0:
                raise failed_for(s)("STL", "scripts/reproduce.py", code)
            if not (stl / "claims.json").is_file():
                raise seeds.SeedRunError(f"{name}: reproduce.py exited 0 but wrote no claims.json")
            with lock:
                folder.finish(name, {"wall_s": round(time.perf_counter() - t, 3)})
        except BaseException:
            stop.set()
            raise
        note(f"{name}: done; {headline(write())}")

    write()
    calls = [functools.partial(unit, s, k) for s in seeds_ for k in scales]
    errors = seeds.side_by_side(jobs, calls, procs, lock, stop)
    doc = write()
    # This session's wall and CPU time, kept for the totals of a later --resume.
    session = {"wall_s": before.get("wall_s", 0.0) + time.perf_counter() - started,
               "cpu_s": before.get("cpu_s", 0.0) + _children_cpu() - cpu0}  # fmt: skip
    folder.units["_session"] = session
    if errors:
        folder.finish("_session", session)
        raise errors[0]
    folder.finish("_session", session)
    folder.complete()
    return doc
