"""The paper's claims across LTL seeds: the whole protocol on N fresh seeds, resumable per seed.

For each GA seed s, :func:`ltl_ledger` runs as subprocesses ``jaxais.scripts.evolve --out
OUT/ltl/seed_s --seed s`` (the LTL) then ``jaxais.scripts.reproduce --seeds OUT/ltl/seed_s/seed
--out OUT/stl/seed_s --seed s --no-baseline`` (the STL), and rebuilds ``OUT/seeds.json``,
``seeds.md`` and ``run.json`` after every seed. ``OUT/manifest.json`` records the finished seeds;
on ``resume`` an LTL with a complete checkpoint but no seed continues with ``--resume`` (see
:func:`ltl_state`) and an STL that reproduce.py began finishes with its own ``--resume`` (same
bits). Nothing here imports JAX: the subprocesses have the device.
"""

from __future__ import annotations

import contextlib
import functools
import json
import operator
import os
import shutil
import signal
import statistics
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor, as_completed
from pathlib import Path
from typing import Any

from jaxais import children, io
from jaxais.experiments import protocol
from jaxais.io import MANIFEST, ON_SIGNAL, Run, atomic_write_json, atomic_write_text, open_run
from jaxais.lock import scoped

__all__ = ["SeedRunError", "headline", "ltl_ledger", "ltl_state", "markdown", "summarise"]

FORMAT = "jaxais-seeds/1"
MAX_SEED = 2**31 - 1  # evolve.py's largest --seed


def seed_range(count: int, first: int) -> range:
    """The scripts' ``--seeds COUNT --first FIRST`` as the seeds they name (one-line errors)."""
    if count < 1:
        raise ValueError(f"--seeds must be >= 1, got {count}")
    if not 0 <= first <= MAX_SEED - count + 1:
        raise ValueError(f"--first must be in [0, {MAX_SEED - count + 1}], got {first}")
    return range(first, first + count)


SYSTEMS = ("SIE", "SRL")  # the seeded systems whose failures and lock-ups the ledger shows
# reproduce.py flags the ledger sets itself (not allowed in ``extra_args``).
RESERVED = ("--out", "--seeds", "--seed", "--no-baseline", "--baseline", "--evolve", "--trials",
            "--contender")  # fmt: skip

Runner = Callable[[list[str], Path | None], int]  # (command, log file or None) -> exit status


class SeedRunError(RuntimeError):
    """A seed's LTL or STL subprocess failed; the message names the seed and the stage."""


def _read_json(path: Path) -> Any:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def _get(doc: Any, *keys: str) -> Any:
    """``doc[k1][k2]...``, or None where a level is missing."""
    for key in keys:
        if not isinstance(doc, Mapping) or key not in doc:
            return None
        doc = doc[key]
    return doc


def ltl_state(path: str | Path) -> str:
    """What an LTL folder needs: "done", "resume" (a complete GA checkpoint but no finished
    seed: evolve.py ``--resume``) or "fresh"."""
    path = Path(path)
    seed = (path / "seed" / "seed.json").is_file()
    if seed and (path / "summary.json").is_file():
        return "done"
    ck = path / "checkpoints"  # orbax names complete checkpoints by their step
    if ck.is_dir() and any(p.is_dir() and p.name.isdigit() for p in ck.iterdir()):
        return "resume"
    return "done" if seed else "fresh"  # a seed without its summary is used as it is


def _seed_row(docs: Mapping[str, Any]) -> dict[str, Any]:
    """One seed's line of the ledger from its tables, claims and LTL documents."""
    tables, claims = docs["tables"], docs["claims"]
    ltl_summary, ltl_seed = docs.get("ltl_summary") or {}, docs.get("ltl_seed") or {}
    worlds = list(tables["table5"])
    row = {
        "claims_held": claims["summary"]["reproduced"],
        "claims_total": claims["summary"]["total"],
        "held": [c["id"] for c in claims["claims"] if c.get("held") is True],
        "hypotheses": {h: bool(v["supported"]) for h, v in tables["hypotheses"].items()},
        "failure_pct": {
            w: {k: _get(tables, "table5", w, k, "total") for k in SYSTEMS} for w in worlds
        },
        "locked_s": {w: {k: _get(tables, "locked_s", w, k) for k in SYSTEMS} for w in worlds},
        "trapped_s": {w: _get(tables, "trapped_s", w, "SIE") for w in worlds},
        "difference_rate": {w: _get(tables, "idiotypic_difference_rate", w, "SIE") for w in worlds},
        "ltl": {
            "generations": ltl_seed.get("generations", ltl_summary.get("generations_run")),
            "stopped_by": ltl_summary.get("stopped_by"),
            "crossing_rate": _get(ltl_seed, "crossing", "rate"),
        },
        "wall_s": docs.get("wall_s"),
    }
    labels = _get(tables, "contenders", "contenders") or {}
    if labels:  # each contender's mean f and Table 4's level of its f against SIE's, per world
        row["contenders"] = {
            label: {
                w: {
                    "f": _get(tables, "contenders", "table3", w, label, "f"),
                    "level_vs_SIE": _get(tables, "contenders", "table4", w, f"{label} vs SIE", "f"),
                }
                for w in worlds
            }
            for label in labels
        }
    return row


def summarise(
    per_seed: Mapping[int, Mapping[str, Any]], requested: Iterable[int] | None = None
) -> dict[str, Any]:
    """The ``seeds.json`` ledger over finished seeds (of ``requested``, default all).

    ``per_seed``: seed -> {"tables", "claims"} and optionally "ltl_summary" (evolve.py's
    summary.json), "ltl_seed" (seed/seed.json), "wall_s" ({"ltl": s, "stl": s}).
    """
    seeds = sorted(per_seed)
    wanted = sorted(set(seeds if requested is None else requested))
    rows = {s: _seed_row(per_seed[s]) for s in seeds}
    n = len(rows)
    texts: dict[str, str] = {}
    for s in seeds:
        for claim in per_seed[s]["claims"]["claims"]:
            texts.setdefault(claim["id"], claim.get("text", ""))
    claims = {}
    for cid, text in texts.items():
        k = sum(cid in rows[s]["held"] for s in seeds)
        claims[cid] = {"text": text, "held_on": k, "of": n, "fraction": k / n}
    names = list(dict.fromkeys(h for s in seeds for h in rows[s]["hypotheses"]))
    hypotheses = {}
    for h in names:
        on = [s for s in seeds if rows[s]["hypotheses"].get(h)]
        hypotheses[h] = {"held_on": len(on), "of": n, "seeds": on}
    counts = [rows[s]["claims_held"] for s in seeds]
    held = dict.fromkeys(("median", "min", "max", "of"))
    if counts:
        total = max(rows[s]["claims_total"] for s in seeds)
        held = dict(median=statistics.median(counts), min=min(counts), max=max(counts), of=total)
    return {
        "format": FORMAT,
        "seeds": {str(s): rows[s] for s in seeds},
        "claims": claims,
        "hypotheses": hypotheses,
        "claims_held": held,
        "complete": set(wanted) <= set(seeds),
        "done": sum(s in rows for s in wanted),
        "requested": len(wanted),
        "requested_seeds": wanted,
    }


def headline(summary: Mapping[str, Any]) -> str:
    """One line: claims held (median, range) and each hypothesis's count, over the done seeds."""
    n, held, k = summary["done"], summary["claims_held"], len(summary["seeds"])
    if not summary["seeds"]:
        return f"claims held: no seed done (0 of {summary['requested']})"
    parts = [
        f"claims held: median {held['median']:g} (range {held['min']}-{held['max']} of "
        f"{held['of']}) over {k} seed{'s' * (k != 1)}"
    ]
    parts += [f"{h} on {v['held_on']} of {v['of']}" for h, v in summary["hypotheses"].items()]
    partial = "" if summary["complete"] else f" ({n} of {summary['requested']} seeds done)"
    return "; ".join(parts[:2]) + "".join(f", {p}" for p in parts[2:]) + partial


def _fmt(x: float | None, digits: int = 0, scale: float = 1.0) -> str:
    return "–" if x is None else f"{x * scale:.{digits}f}"


def _pair(row: Mapping[str, Any], key: str, world: str) -> str:
    """SIE's and SRL's ``row[key][world]``, as "a / b"."""
    return " / ".join(_fmt(_get(row, key, world, k)) for k in SYSTEMS)


def markdown(summary: Mapping[str, Any]) -> str:
    """``seeds.md``: per-seed table, per-claim frequencies, hypotheses, and how it was made."""
    rows, hyps = summary["seeds"], list(summary["hypotheses"])
    worlds = list(dict.fromkeys(w for r in rows.values() for w in r["failure_pct"]))
    status = "complete" if summary["complete"] else "partial: run it again with --resume"
    held = summary["claims_held"]
    held_line = "Claims held: no seed done yet."
    if rows:
        held_line = f"Claims held: median {held['median']:g}, range {held['min']}-{held['max']}"
        held_line += f" of {held['of']}."
    lines = [
        "# The paper's claims across LTL seeds",
        "",
        f"{summary['done']} of {summary['requested']} seeds done ({status}).",
        "",
        held_line,
        "",
        "## Per seed",
        "",
        "Failure % and lock-up time (s) as SIE / SRL; difference rate: SIE's idiotypic "
        "difference rate, %.",
        "",
    ]
    head = ["seed", "generations", "claims held", *hyps]
    head += [f"fail % {w}" for w in worlds] + [f"lock-up s {w}" for w in worlds]
    head += [f"SIE diff % {w}" for w in worlds]
    lines += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for s, r in rows.items():
        cells = [s, str(r["ltl"]["generations"]), f"{r['claims_held']} of {r['claims_total']}"]
        cells += ["✓" if r["hypotheses"].get(h) else "✗" for h in hyps]
        cells += [_pair(r, "failure_pct", w) for w in worlds]
        cells += [_pair(r, "locked_s", w) for w in worlds]
        cells += [_fmt(r["difference_rate"].get(w), 1, 100.0) for w in worlds]
        lines.append("| " + " | ".join(cells) + " |")
    labels = list(dict.fromkeys(c for r in rows.values() for c in r.get("contenders", {})))
    if labels:
        lines += ["", "## Contenders", ""]
        lines += ["Mean f, and Table 4's significance level of its difference from SIE's (99: "
                  "significant at the paper's level).", ""]  # fmt: skip
        head = ["seed", *(f"{c} f (level) {w}" for c in labels for w in worlds)]
        lines += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        for s, r in rows.items():
            cells = [s]
            for c in labels:
                for w in worlds:
                    cell = _get(r, "contenders", c, w) or {}
                    cells.append(f"{_fmt(cell.get('f'))} ({_fmt(cell.get('level_vs_SIE'))})")
            lines.append("| " + " | ".join(cells) + " |")
    lines += ["", "## Claims, by the fraction of seeds they hold on", ""]
    lines += ["| claim | held on | text |", "|---|---:|---|"]
    ranked = sorted(summary["claims"].items(), key=lambda kv: -kv[1]["fraction"])  # stable
    for cid, c in ranked:
        lines.append(f"| {cid} | {c['held_on']} of {c['of']} | {c['text']} |")
    lines += ["", "## Hypotheses", ""]
    lines.append(
        "; ".join(
            f"{h}: {v['held_on']} of {v['of']} seeds ({', '.join(map(str, v['seeds'])) or 'none'})"
            for h, v in summary["hypotheses"].items()
        )
        or "no seed done."
    )
    lines += ["", "## How it was made", ""]
    if summary.get("command"):
        lines += [f"`{summary['command']}`", ""]
    lines.append(
        "For each seed s: `scripts/evolve.py --out ltl/seed_s --seed s` (the LTL, evolve.py's "
        "defaults), then `scripts/reproduce.py --seeds ltl/seed_s/seed --out stl/seed_s --seed s "
        "--no-baseline` (the paper's protocol); each seed's files lie in those folders."
    )
    return "\n".join(lines) + "\n"


class _Processes:
    """The default runner: child processes, remembered so that an interrupted ledger stops them
    (and ended by the kernel if this process is killed: :mod:`jaxais.children`)."""

    def __init__(self) -> None:
        self._lock, self._live, self._stopped = threading.Lock(), set(), False

    def __call__(self, cmd: list[str], log: Path | None) -> int:
        if log is not None:
            log.parent.mkdir(parents=True, exist_ok=True)
        with contextlib.nullcontext() if log is None else open(log, "w") as stream:
            with self._lock:
                if self._stopped:
                    return -int(signal.SIGTERM)
                err = None if stream is None else subprocess.STDOUT
                proc = children.popen(cmd, stdout=stream, stderr=err)  # dies with this one
                self._live.add(proc)
            try:
                return proc.wait()
            finally:
                with self._lock:
                    self._live.discard(proc)

    def stop(self) -> None:
        """SIGTERM to every child (evolve.py keeps its last checkpoint), SIGKILL after 60 s."""
        with self._lock:
            self._stopped, live = True, list(self._live)
        for proc in live:
            proc.terminate()
        for proc in live:
            try:
                proc.wait(timeout=60)
            except subprocess.TimeoutExpired:
                proc.kill()


def _paths(out: Path, s: int) -> tuple[Path, Path]:
    """(LTL folder, STL folder) of seed ``s``."""
    return out / "ltl" / f"seed_{s}", out / "stl" / f"seed_{s}"


def _documents(folder: Run, s: int) -> dict[str, Any]:
    ltl, stl = _paths(folder.out, s)
    docs = {k: _read_json(stl / f"{k}.json") for k in ("tables", "claims")}
    for k, doc in docs.items():
        if not isinstance(doc, dict):
            raise ValueError(f"{stl / f'{k}.json'}: missing or not JSON; use a fresh --out")
    docs["ltl_summary"] = _read_json(ltl / "summary.json")
    docs["ltl_seed"] = _read_json(ltl / "seed" / "seed.json")
    docs["wall_s"] = {
        "ltl": _get(docs["ltl_summary"], "wall_time_total_s"),
        "stl": folder.units[f"seed {s}"]["stl_wall_s"],
    }
    return docs


def _versions(out: Path, done: Iterable[int]) -> dict[str, Any]:
    """The first done seed's reproduce.py versions, else the installed packages' (JAX not
    started: on a GPU it would take the memory the subprocesses need)."""
    for s in done:
        found = _get(_read_json(_paths(out, s)[1] / "run.json"), "versions")
        if isinstance(found, dict):
            return found
    import platform
    from importlib import metadata

    versions: dict[str, Any] = {"python": platform.python_version(), "backend": None}
    for name in ("jaxais", "jax", "jaxlib", "numpy"):
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = None
    return versions


def default_jobs() -> int:
    """Seeds side by side by default: one per core this process may use. The GA runs on one
    core (evolve.py keeps one device) in about 400 MB, so a 2-core machine runs two seeds'
    LTLs at once instead of one after another; the compilation cache then serves every later
    seed's programs."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return max(1, cores or 1)


def _contender_records(specs: Sequence[str]) -> list[dict[str, str | None]]:
    """Each ``--contender`` spec checked (form, label, file) with its file's sha256 (None for a
    module's spec)."""
    from jaxais.experiments.contenders import check_specs, spec_sha256

    return [{"spec": spec, "sha256": spec_sha256(spec)} for _, spec in check_specs(list(specs))]


def evolve(ltl: Path, s: int, run: Runner, log: Path | None, note, failed) -> None:
    """The LTL of seed ``s`` in ``ltl`` unless done (``evolve.py --seed s``, resumed from its
    checkpoint where one is complete: :func:`ltl_state`); ``failed(stage, script, code)`` makes
    the error of a failed run."""
    state = ltl_state(ltl)
    if state == "done":
        return
    cmd = [sys.executable, "-m", "jaxais.scripts.evolve", "--out", str(ltl), "--seed", str(s)]
    note(f"seed {s}: LTL {'resumed' if state == 'resume' else 'started'} ({ltl})")
    code = run(cmd + ["--resume"] * (state == "resume"), log)
    if code != 0:
        raise failed("LTL", "scripts/evolve.py", code)
    if not (ltl / "seed" / "seed.json").is_file():
        raise SeedRunError(f"seed {s}: scripts/evolve.py exited 0 but wrote no {ltl}/seed")


def _run_seed(folder: Run, s: int, settings: dict, run: Runner, logs: bool, note, stop) -> float:
    """Seed ``s``'s LTL (unless done) and STL. Returns the STL's wall time."""
    ltl, stl = _paths(folder.out, s)

    def log(stage: str) -> Path | None:
        return folder.out / "logs" / f"seed_{s}.{stage}.log" if logs else None

    def failed(stage: str, script: str, code: int) -> SeedRunError:
        where = f"see {log(stage.lower())}" if logs else "see its messages above"
        return SeedRunError(f"seed {s}: the {stage} ({script}) failed, exit status {code}; {where}")

    evolve(ltl, s, run, log("ltl"), note, failed)
    if stop.is_set():
        return -1.0
    resume = (stl / MANIFEST).is_file()  # reproduce.py began: it finishes its own partial run
    if stl.exists() and not resume:
        shutil.rmtree(stl)  # killed before reproduce.py wrote anything
    cmd = [sys.executable, "-m", "jaxais.scripts.reproduce", "--seeds", str(ltl / "seed"),
           "--out", str(stl), "--seed", str(s), "--no-baseline"]  # fmt: skip
    if settings["trials"] is not None:
        cmd += ["--trials", str(settings["trials"])]
    for c in settings.get("contenders", ()):
        cmd += ["--contender", c["spec"]]
    cmd += ["--resume"] * resume
    note(f"seed {s}: STL {'resumed' if resume else 'started'} ({stl})")
    t = time.perf_counter()
    code = run(cmd + settings["extra_args"], log("stl"))
    if code != 0:
        raise failed("STL", "scripts/reproduce.py", code)
    if not (stl / "report.md").is_file():
        raise SeedRunError(f"seed {s}: scripts/reproduce.py exited 0 but wrote no {stl}/report.md")
    return round(time.perf_counter() - t, 3)


@scoped  # its folder's lock goes when it returns or raises
def ltl_ledger(
    out: str | Path,
    seeds: Iterable[int] = range(10),
    trials: int | None = None,
    jobs: int | None = None,
    extra_args: Sequence[str] = (),
    progress: bool = True,
    *,
    contenders: Sequence[str] = (),
    command: str | None = None,
    runner: Runner | None = None,
    resume: bool = False,
) -> dict[str, Any]:
    """Run the LTL and the paper's protocol on every seed (each unless done); return the ledger.

    Args:
        seeds: the GA seeds (each also the STL's trial seed).
        trials: reproduce.py's ``--trials`` (default: the paper's counts).
        jobs: seeds run side by side (default: one per core, :func:`default_jobs`); above 1
            subprocesses log to ``OUT/logs/seed_s.{ltl,stl}.log``.
        extra_args: further reproduce.py flags (``--worlds``, ``--tau-cap``, ...).
        contenders: reproduce.py's ``--contender`` specs (``[LABEL=]FILE.py:NAME``), run on
            every seed; each file's sha256 is recorded, so a resume refuses a changed file.
        runner: runs one subprocess (tests inject one); default: a child process of this one.

    Raises:
        ValueError: bad arguments, or ``out`` holding another run (or none to resume).
        SeedRunError: a subprocess failed (after the running seeds finished and were written).
    """
    io.check_memory(operator.length_hint(seeds), io.RUN_BYTES, "--seeds")  # before listing them
    out, seeds = Path(out), list(seeds)
    if not seeds or len(set(seeds)) != len(seeds):
        raise ValueError(f"seeds must be distinct and at least one, got {seeds}")
    if any(not isinstance(s, int) or isinstance(s, bool) or not 0 <= s <= MAX_SEED for s in seeds):
        raise ValueError(f"seeds must be integers in [0, {MAX_SEED}], got {seeds}")
    if trials is not None and trials < 2:
        raise ValueError(f"--trials must be >= 2 (t-tests need two per group), got {trials}")
    jobs = default_jobs() if jobs is None else jobs
    if isinstance(jobs, bool) or not isinstance(jobs, int) or jobs < 1:
        raise ValueError(f"--jobs must be an integer >= 1, got {jobs!r}")
    if trials is not None:  # --jobs reproduce.py side by side, each with reproduce.py's pool
        runs = max(len(protocol.systems_for_world(w)) for w in protocol.WORLDS) + 2
        io.check_memory(trials, min(jobs, len(seeds)) * runs * io.RUN_BYTES, "--trials")
    extra = [str(a) for a in extra_args]
    if any(a.split("=")[0] in RESERVED for a in extra):
        raise ValueError(f"extra_args may not set {', '.join(RESERVED)} (the ledger sets them)")
    settings = {"trials": trials, "extra_args": extra}
    if contenders:  # recorded only when given: earlier ledgers' manifests stay valid
        settings["contenders"] = _contender_records(contenders)
    if command is None:
        command = f"ltl_ledger({str(out)!r}, seeds={seeds}, trials={trials}, extra_args={extra})"
    folder = open_run(out, "seeds", {"seeds": seeds, **settings}, resume=resume)
    lock, stop, procs = threading.Lock(), threading.Event(), _Processes()
    run = runner or procs

    def note(text: str) -> None:
        if progress:
            print(text, file=sys.stderr, flush=True)

    def write() -> dict[str, Any]:
        with lock:
            done = {s: _documents(folder, s) for s in seeds if f"seed {s}" in folder.units}
            summary = summarise(done, seeds) | {"command": command}
            atomic_write_json(out / "seeds.json", summary)
            atomic_write_text(out / "seeds.md", markdown(summary))
            run_doc = {"command": command, "seeds": seeds, "jobs": jobs, **settings}
            run_doc["versions"] = _versions(out, done)
            run_doc["wall_s"] = {str(s): d["wall_s"] for s, d in done.items()}
            atomic_write_json(out / "run.json", run_doc)
            return summary

    def pipeline(s: int) -> None:
        try:
            if stop.is_set() or f"seed {s}" in folder.units:
                return
            wall = _run_seed(folder, s, settings, run, jobs > 1, note, stop)
            if wall < 0:  # stopped between its LTL and its STL
                return
            with lock:
                folder.finish(f"seed {s}", {"stl_wall_s": wall})
        except BaseException:
            stop.set()  # here, before this worker takes the next seed
            raise
        note(f"seed {s}: done; {headline(write())}")

    write()
    errors = side_by_side(jobs, [functools.partial(pipeline, s) for s in seeds], procs, lock, stop)
    if errors:
        raise errors[0]
    summary = write()
    folder.complete()
    return summary


def side_by_side(jobs: int, calls: Sequence[Callable[[], None]], procs: Any,
                 lock: threading.Lock, stop: threading.Event) -> list[Exception]:  # fmt: skip
    """Run ``calls`` ``jobs`` at a time (threads, each waiting on its children ``procs``) and
    return the errors of those that failed: the ones already running finish, no new one starts
    (each call sets ``stop`` as it fails). A signal that ends the script stops the children
    and lets a write in flight (under ``lock``) end."""

    def on_signal() -> None:
        procs.stop()
        lock.acquire(timeout=2)

    pool, errors = ThreadPoolExecutor(max_workers=jobs), []
    ON_SIGNAL.append(on_signal)
    try:
        for future in as_completed([pool.submit(call) for call in calls]):
            try:
                future.result()
            except Exception as err:
                errors.append(err)
    except BaseException:
        stop.set()
        procs.stop()
        raise
    finally:
        ON_SIGNAL.remove(on_signal)
        pool.shutdown(wait=True, cancel_futures=True)
    return errors
