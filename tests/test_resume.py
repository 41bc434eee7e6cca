"""Results folders that say what they hold, and ``--resume`` (``jaxais.io.open_run``).

The manifest's rules are checked on the library alone. Each long-running script (sweep.py,
ablate.py, train_baseline.py, the seed ledger; reproduce.py in ``tests/test_scripts_stl.py``,
beside its reference run) is killed by a signal at a moment read from its manifest (no fixed
sleeps), resumed, and its results compared with an uninterrupted run's, exactly. Tiny runs share
one compilation cache, so each program compiles once.
"""

from __future__ import annotations

import hashlib
import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import _stl_fixtures as F
import numpy as np
import pytest
from _python import call_main, start_script
from test_seeds import FakeScripts

from jaxais.io import MANIFEST, UserError, open_run

EXIT = {signal.SIGINT: 130, signal.SIGTERM: 143, signal.SIGKILL: -9}


# ------------------------------------------------------------------------------- the manifest


def _manifest(out: Path) -> dict:
    return json.loads((out / MANIFEST).read_text())


def test_a_fresh_run_needs_an_empty_folder_and_says_at_once_that_it_is_partial(tmp_path):
    run = open_run(tmp_path / "new", "sweep", {"trials": 2, "grid": ("k1=1",)})
    body = {"kind": "sweep", "status": "partial", "config": {"grid": ["k1=1"], "trials": 2},
            "units": {}}  # fmt: skip
    canonical = '{"config":{"grid":["k1=1"],"trials":2},"kind":"sweep","status":"partial",'
    canonical += '"units":{}}'
    assert _manifest(tmp_path / "new") == body | {
        "checksum": hashlib.sha256(canonical.encode()).hexdigest()  # sorted keys, no spaces
    }
    run.finish("points 0-0", {"mean": 1.5})
    assert _manifest(run.out)["units"] == {"points 0-0": {"mean": 1.5}}
    run.complete()
    assert _manifest(run.out)["status"] == "complete"
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("a user's file")
    with pytest.raises(UserError, match=r"mine is not empty and holds no run: give a fresh or"):
        open_run(mine, "sweep", {})
    assert [p.name for p in mine.iterdir()] == ["notes.txt"]
    (tmp_path / "file").write_text("")
    with pytest.raises(UserError, match=r"file: not a directory"):
        open_run(tmp_path / "file", "sweep", {})


def test_another_run_in_the_folder_is_refused_in_one_line(tmp_path):
    out = tmp_path / "r"
    cfg = {"trials": 2, "seed": 0}
    run = open_run(out, "reproduce", cfg)
    run.finish("world1", {"run_s": 1.0})
    cases = [
        ({}, rf"^{out} holds a partial reproduce run: finish it with --resume, or give a fresh "
             "--out$"),
        ({"resume": True, "config": {"trials": 4, "seed": 0}},
         rf"^--trials: the run in {out} has 2, not 4; resume it with the same settings, or give"),
        ({"resume": True, "config": {"trials": 2}}, r"^--seed: the run in .* has 0, not null;"),
        ({"resume": True, "kind": "sweep"}, rf"^{out} holds a reproduce run, not a sweep run"),
    ]  # fmt: skip
    for kw, message in cases:
        args = {"kind": "reproduce", "config": cfg} | kw
        with pytest.raises(UserError, match=message):
            open_run(out, args.pop("kind"), args.pop("config"), **args)
    assert open_run(out, "reproduce", cfg, resume=True).units == {"world1": {"run_s": 1.0}}
    # A process of a multi-process run that does not write checks nothing and reads the units.
    assert open_run(out, "reproduce", {}, write=False).units == {}
    assert open_run(out, "reproduce", {}, resume=True, write=False).units == run.units
    run.complete()
    with pytest.raises(UserError, match="holds a complete reproduce run: remove it or give a"):
        open_run(out, "reproduce", cfg)
    with pytest.raises(UserError, match=rf"^{tmp_path / 'none'}: no run to resume \(no manif"):
        open_run(tmp_path / "none", "reproduce", cfg, resume=True)
    assert not (tmp_path / "none").exists()
    (out / MANIFEST).write_text('["not", "a", "manifest"]')
    with pytest.raises(UserError, match=r"manifest.json: not a run manifest \(.*\); use a fresh"):
        open_run(out, "reproduce", cfg, resume=True)


def test_a_hand_edited_or_damaged_manifest_is_refused_and_an_old_one_taken_once(tmp_path):
    cfg = {"trials": 2, "seed": 0}
    run = open_run(tmp_path / "r", "reproduce", cfg)
    run.finish("world1", {"run_s": 1.0})
    run.lock.release()  # as its process ended
    path = tmp_path / "r" / MANIFEST
    good = path.read_text()
    edits = {
        "settings": good.replace('"trials": 2', '"trials": 4'),
        "units": good.replace('"run_s": 1.0', '"run_s": 2.0'),
        "status": good.replace('"partial"', '"complete"'),
        "checksum": good.replace('"checksum": "', '"checksum": "0'),
    }
    for name, text in edits.items():
        assert text != good, name
        path.write_text(text)
        with pytest.raises(UserError) as err:
            open_run(tmp_path / "r", "reproduce", json.loads(text)["config"], resume=True)
        assert str(err.value) == (
            f"{path}: its checksum does not match its contents (edited by hand or damaged), so "
            "the run there cannot be trusted to resume: start it again with a fresh --out"
        ), name
        assert path.read_text() == text  # nothing written
    # A manifest from before checksums is taken as it is, and has one once saved again.
    old = json.loads(good)
    del old["checksum"]
    path.write_text(json.dumps(old))
    again = open_run(tmp_path / "r", "reproduce", cfg, resume=True)
    assert again.units == {"world1": {"run_s": 1.0}}
    again.finish("world2")
    assert (
        _manifest(tmp_path / "r")["checksum"]
        == hashlib.sha256(
            json.dumps(
                {**old, "units": again.units}, sort_keys=True, separators=(",", ":")
            ).encode()
        ).hexdigest()
    )


def test_resume_removes_the_temporary_files_a_sigkill_left(tmp_path):
    run = open_run(tmp_path, "ablate", {})
    (tmp_path / "batches").mkdir()
    cut = [tmp_path / ".run.json.k2j3h4g5.json", tmp_path / "batches" / ".0.json.abcdefgh.json"]
    for p in cut:
        p.write_text("{")
    (tmp_path / "batches" / "0.json").write_text("{}")
    open_run(tmp_path, "ablate", {}, resume=True)
    assert not any(p.exists() for p in cut) and (tmp_path / "batches" / "0.json").exists()
    assert run.units == {}


# ------------------------------------------------------------------------- killing the scripts


@pytest.fixture(scope="module")
def cache(tmp_path_factory) -> dict[str, str]:
    """One compilation cache for every script run here: each program compiles once."""
    d = tmp_path_factory.mktemp("xla_cache")
    return {"JAXAIS_CACHE_DIR": str(d)}


def finish(proc: subprocess.Popen, status: int = 0) -> tuple[str, str]:
    out, err = proc.communicate(timeout=600)
    assert proc.returncode == status, err[-3000:]
    return out, err


def kill_after(proc: subprocess.Popen, out: Path, units: int, sig: signal.Signals) -> None:
    """Send ``sig`` once ``out``'s manifest lists ``units`` finished units (0: once it exists),
    and check that the script ended by it: one line for SIGINT and SIGTERM, no temporary file."""
    deadline = time.monotonic() + 600
    while proc.poll() is None and time.monotonic() < deadline:
        try:
            if len(_manifest(out)["units"]) >= units:
                break
        except (OSError, ValueError):
            pass
        time.sleep(0.02)
    proc.send_signal(sig)
    _, err = finish(proc, EXIT[sig])
    if sig != signal.SIGKILL:
        word = "interrupted" if sig == signal.SIGINT else "terminated"
        assert err.splitlines()[-1].endswith(f": error: {word}"), err[-2000:]
        assert not [p for p in out.rglob(".*") if p.is_file()]
    assert _manifest(out)["status"] == "partial"


@pytest.mark.slow
def test_sweep_interrupted_and_resumed_gives_the_uninterrupted_sweep(tmp_path, cache):
    # 4 chunks of one point each: 4 units.
    args = ("--grid", "k1=0.85,1.6", "--grid", "k2=1.1,2", "--trials", 1, "--slots", 1,
            "--tau-cap", 4)  # fmt: skip
    ref, out = tmp_path / "ref", tmp_path / "out"
    finish(start_script("sweep.py", *args, "--out", ref, **cache))
    # The uninterrupted run, as a user reads it: its record and figure, no machine paths.
    doc = json.loads((ref / "sweep.json").read_text())
    assert doc["runs"] == 4 and len(doc["points"]) == 4
    assert doc["config"]["command"].startswith("sweep.py --grid k1=0.85,1.6")
    assert str(tmp_path) not in json.dumps(doc)
    assert (ref / "sweep.png").stat().st_size > 10_000
    # Like every script, sweep.py keeps its compiled programs in JAXAIS_CACHE_DIR for the next run.
    assert any(p.name.startswith("jit__") for p in Path(cache["JAXAIS_CACHE_DIR"]).iterdir())
    # Killed once (a resumed run killed again: the ledger here, reproduce.py's in
    # tests/test_scripts_stl.py).
    kill_after(start_script("sweep.py", *args, "--out", out, **cache), out, 1, signal.SIGINT)
    finish(start_script("sweep.py", *args, "--out", out, "--resume", **cache))
    a, b = (json.loads((d / "sweep.json").read_text()) for d in (ref, out))
    for key in ("axes", "base_values", "points", "runs", "robot_iterations", "paper_point"):
        assert a[key] == b[key], key
    assert a["config"]["command"].replace("--out ref", "--out out") == b["config"]["command"]
    assert _manifest(ref) == _manifest(out)  # the same units, each point's numbers exactly


@pytest.mark.slow
def test_ablate_killed_after_a_batch_and_resumed_gives_the_same_ablation(tmp_path, cache):
    seeds = F.write_seed(tmp_path / "seed", seed=0)
    # Two batches (another collision rule compiles its own program): two units.
    args = ("--worlds", "world1", "--variants", "ours,collision_rule=entry", "--trials", 2,
            "--tau-cap", 5, "--seeds", seeds)  # fmt: skip
    ref, out = tmp_path / "ref", tmp_path / "out"
    finish(start_script("ablate.py", *args, "--out", ref, **cache))
    # The uninterrupted run's files, as a user reads them: no machine paths.
    assert {p.name for p in ref.iterdir()} >= {
        "ablation.json", "ablation.md", "ablation.png", "run.json",
    }  # fmt: skip
    doc = json.loads((ref / "ablation.json").read_text())
    variants = ["ours", "collision_rule=entry"]
    assert [v["name"] for v in doc["variants"]] == variants
    assert [v["settings"]["collision_rule"] for v in doc["variants"]] == ["episode", "entry"]
    ours = doc["variants"][0]
    assert ours["claims"]["total"] == 32 and 0 <= ours["claims"]["reproduced"] <= 32
    assert len(ours["held"]) == ours["claims"]["reproduced"]
    md = (ref / "ablation.md").read_text()
    assert all(f"| `{name}` |" in md for name in variants)
    assert (ref / "ablation.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    text = (ref / "run.json").read_text()
    assert str(tmp_path) not in text and '"/' not in text
    run = json.loads(text)
    assert run["seed"] == 0 and run["trials"] == {"world1": 2}
    assert [c["variants"] for c in run["calls"]] == [variants[:1], variants[1:]]
    assert {"jaxais", "jax", "numpy"} <= set(run["versions"]) and run["timings_s"]["total_s"] > 0
    kill_after(start_script("ablate.py", *args, "--out", out, **cache), out, 1, signal.SIGTERM)
    bad = call_main("ablate.py", *args[:5], 3, *args[6:], "--out", out, "--resume")
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1  # other settings: refused
    assert "--trials: the run in" in bad.stderr
    finish(start_script("ablate.py", *args, "--out", out, "--resume", **cache))
    for name in ("ablation.json", "ablation.md", "batches/0.json", "batches/1.json"):
        assert (ref / name).read_text() == (out / name).read_text(), name
    runs = [json.loads((d / "run.json").read_text()) for d in (ref, out)]
    for run in runs:
        del run["timings_s"]
        for call in run["calls"]:
            del call["run_s"]
    assert runs[0] == runs[1]


@pytest.mark.slow
def test_train_baseline_killed_and_resumed_trains_the_same_weights(tmp_path, cache):
    args = ("--world", "real", "--generations", 4, "--pairs", 4, "--episodes", 2, "--steps", 60,
            "--hidden", 8, "--no-eval")  # fmt: skip
    ref, out = tmp_path / "ref", tmp_path / "out"
    finish(start_script("train_baseline.py", *args, "--out", ref, **cache))
    kill_after(
        start_script("train_baseline.py", *args, "--out", out, **cache), out, 0, signal.SIGINT
    )
    finish(start_script("train_baseline.py", *args, "--out", out, "--resume", **cache))
    a, b = (json.loads((d / "config.json").read_text()) for d in (ref, out))
    for key in ("final", "curve", "config", "seed", "parameters"):
        assert a[key] == b[key], key
    with np.load(ref / "params.npz") as x, np.load(out / "params.npz") as y:
        assert x.files == y.files and all(np.array_equal(x[k], y[k]) for k in x.files)
    # Resuming a complete run skips its finished stage; no --resume into it is refused.
    before = (out / "params.npz").stat().st_mtime_ns
    again = start_script("train_baseline.py", *args, "--out", out, "--resume", **cache)
    assert "trained in" in finish(again)[0] and (out / "params.npz").stat().st_mtime_ns == before
    fresh = call_main("train_baseline.py", *args, "--out", out)
    nothing = call_main("train_baseline.py", *args, "--out", tmp_path / "none", "--resume")
    for proc, message in ((fresh, "holds a complete train_baseline run"),
                          (nothing, "none: no run to resume")):  # fmt: skip
        assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr
        assert proc.stderr.startswith("train_baseline.py: error: ") and message in proc.stderr
    assert not (tmp_path / "none").exists()
    # Training stops between two compiled generations, not at its end: SIGTERM after the first
    # generation's line ends a run of 100,000 generations in one line, with no weights written.
    long = tmp_path / "long"
    proc = start_script("train_baseline.py", *args[:2], "--generations", 100_000, *args[4:],
                        "--log-every", 1, "--out", long, **cache)  # fmt: skip
    first = proc.stderr.readline()
    proc.send_signal(signal.SIGTERM)
    _, err = finish(proc, EXIT[signal.SIGTERM])
    assert " gen    1/100000: " in first, first
    assert err.splitlines()[-1] == "train_baseline.py: error: terminated", err[-2000:]
    assert _manifest(long)["status"] == "partial" and not (long / "params.npz").exists()


LEDGER = """
import sys, time
sys.path.insert(0, {tests!r})
from test_seeds import FakeScripts  # no JAX: the ledger runs none
from jaxais.cli import main_wrapper
from jaxais.experiments.seeds import ltl_ledger

def slow(cmd, log, fake=FakeScripts()):  # a signal can land between seeds
    time.sleep(0.2)
    return fake(cmd, log)

with main_wrapper("seeds.py"):
    ltl_ledger({out!r}, [0, 1, 2], trials=2, jobs=1, runner=slow, progress=False,
               command="seeds.py", resume={resume})
"""


def test_seed_ledger_killed_twice_and_resumed_gives_the_uninterrupted_ledger(tmp_path):
    from jaxais.experiments.seeds import ltl_ledger

    ref, out = tmp_path / "ref", tmp_path / "out"
    ltl_ledger(ref, [0, 1, 2], trials=2, jobs=1, runner=FakeScripts(), progress=False,
               command="seeds.py")  # fmt: skip

    def ledger(resume: bool) -> subprocess.Popen:
        code = LEDGER.format(tests=str(Path(__file__).parent), out=str(out), resume=resume)
        return subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True)  # fmt: skip

    kill_after(ledger(False), out, 1, signal.SIGTERM)
    kill_after(ledger(True), out, 2, signal.SIGKILL)
    finish(ledger(True))
    a, b = (json.loads((d / "seeds.json").read_text()) for d in (ref, out))
    for doc in (a, b):
        for row in doc["seeds"].values():
            del row["wall_s"]  # the fake's wall times
    assert a == b and b["complete"]
    assert list(_manifest(out)["units"]) == ["seed 0", "seed 1", "seed 2"]
