"""scripts/evolve.py: outputs, reproducibility, exact resume, interruption and user errors.

The runs call the script's ``main`` in this process with the tiny GA config of ``test_ga.py``
(shared compiled programs). Subprocesses: the flag errors, which answer before anything is
compiled, one tiny run exactly as a user starts it, and a run that SIGTERM ends (the signal
ends the process at once).
"""

from __future__ import annotations

import hashlib
import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from _python import run_python, script_env
from test_ga import TINY

from jaxais import ga
from jaxais.checkpointing import GACheckpointer
from jaxais.experiments import evolution
from jaxais.seed import load_seed

SCRIPT = Path(__file__).resolve().parent.parent / "scripts" / "evolve.py"
_spec = importlib.util.spec_from_file_location("evolve_script", SCRIPT)
evolve = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(evolve)

TINY_ARGS = [
    *("--populations", "2", "--robots", "4", "--tau-cap", "2"),
    *("--starts", "1", "--success-starts", "4", "--crossing-starts", "8"),
]
"""test_ga's TINY config; the crossing measurement runs in batches of 2 sets x 4 starts, the
size of every other rollout here (one compiled program)."""
assert TINY.tau_cap == 2.0 and (TINY.populations, TINY.robots) == (2, 4)
assert (TINY.starts, TINY.success_starts) == (1, 4)
TIME_KEYS = {
    "wall_s",
    "wall_time_s",
    "ga_wall_time_s",
    "compile_time_s",
    "ga_compile_time_s",
    "wall_time_total_s",
    "crossing_wall_time_s",
}

# After a failed restore, orbax's abandoned reads post to a closed asyncio loop; a late report can
# reach pytest's unraisable hook, which turns it into a warning about nothing of ours.
pytestmark = pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning")


def run_main(*args: str) -> dict:
    return evolve.run([*TINY_ARGS, *args])


def expect_exit(capsys, *args: str, status: int = 2) -> str:
    """Run main expecting ``status``; return the last stderr line (checked: no traceback)."""
    capsys.readouterr()
    with pytest.raises(SystemExit) as info:
        run_main(*args)
    assert info.value.code == status
    err = capsys.readouterr().err
    assert "Traceback" not in err
    last = err.strip().splitlines()[-1]
    assert last.startswith("evolve.py: error: ")
    return last


def seed_arrays(path: Path) -> dict[str, np.ndarray]:
    seed, _ = load_seed(path)
    out = {f"ab_{k}": np.asarray(v) for k, v in vars(seed.antibodies).items()}
    out.update(tau=seed.tau, collisions=seed.collisions, L=seed.L)
    return out


def assert_same_arrays(a: dict[str, np.ndarray], b: dict[str, np.ndarray]) -> None:
    assert a.keys() == b.keys()
    for k in a:
        assert a[k].dtype == b[k].dtype, k
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)


def without_times(obj):
    if isinstance(obj, dict):
        return {k: without_times(v) for k, v in obj.items() if k not in TIME_KEYS}
    if isinstance(obj, list):
        return [without_times(v) for v in obj]
    return obj


def final_checkpoint(out: Path, generations: int):
    config = ga.GAConfig(**{**TINY.to_dict(), "generations": generations})
    info = json.loads((out / "checkpoints" / "run.json").read_text())
    info.pop("format")
    with GACheckpointer(out / "checkpoints", info, resume=True) as ck:
        return ck.restore(config)[0]


@pytest.fixture(scope="module")
def full_run(tmp_path_factory) -> Path:
    """An uninterrupted 3-generation tiny run."""
    out = tmp_path_factory.mktemp("full") / "run"
    run_main("--generations", "3", "--out", str(out))
    return out


# ------------------------------------------------------------------------------- outputs


@pytest.mark.slow
def test_outputs(full_run: Path):
    summary = json.loads((full_run / "summary.json").read_text())
    assert summary["config"]["populations"] == 2 and summary["generations_run"] == 3
    assert [h["generation"] for h in summary["generations"]] == [0, 1, 2]
    assert summary["version"] and summary["seed"] == 0 and summary["world"] == "ga_maze"
    assert summary["command"].startswith("evolve.py ")
    for p in summary["populations"]:
        assert {"best_f_generation_0", "best_f_final_generation", "best_f_overall"} <= p.keys()
        assert p["best_f_overall"] <= p["best_f_generation_0"]
    assert summary["wall_time_s"] > 0 and summary["compile_time_s"] >= 0
    assert (full_run / "fitness.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    seed, meta = load_seed(full_run / "seed")
    assert seed.antibodies.type.shape == (2, 8)
    assert meta["generations"] == 3 and meta["world"] == "ga_maze" and meta["seed"] == 0
    assert meta["command"] == summary["command"] and meta["version"] == summary["version"]
    np.testing.assert_array_equal(seed.tau, [p["best_tau"] for p in summary["populations"]])
    assert sorted(p.name for p in (full_run / "checkpoints").iterdir()) == ["2", "3", "run.json"]
    # Nothing crosses the maze in 2 s: the run ends at its generation cap, rates 0.
    assert summary["stopped_by"] == "generations"
    crossing = summary["crossing"]
    assert crossing == meta["crossing"]
    assert crossing["starts"] == 8 and crossing["tau_cap"] == 2.0 and crossing["rate"] == [0.0] * 2
    assert [p["crossing_rate"] for p in summary["populations"]] == crossing["rate"]
    for p in summary["populations"]:
        assert p["best_starts"] >= 4 and p["best_crossings"] == 0
    first = summary["generations"][0]["populations"][0]
    assert {"best_crossings", "crossing_rate", "best_so_far"} <= first.keys()
    # The flags' operators (jaxais.ga.operators), by name in the summary, seed and checkpoints.
    names = {"selection": "roulette", "crossover": "uniform", "mutation": "resample(0.05)"}
    assert summary["operators"] == meta["operators"] == names
    info = json.loads((full_run / "checkpoints" / "run.json").read_text())
    info.pop("format")
    with GACheckpointer(full_run / "checkpoints", info, resume=True) as ck:
        assert ck.restore(TINY, 2)[1]["operators"] == names


def test_flag_defaults_are_the_ga_defaults():
    args = evolve.parse_args(["--out", "x"])
    assert args.config == ga.GAConfig()
    assert args.crossing_starts == ga.CROSSING_STARTS


@pytest.mark.slow
def test_check_seed_measures_the_recorded_rates(full_run: Path, capsys):
    """``--check-seed`` with the run's settings measures exactly what the run recorded, and
    writes nothing."""
    before = _digest(full_run)
    capsys.readouterr()
    summary = evolve.run([*TINY_ARGS, "--check-seed", str(full_run / "seed")])
    _, meta = load_seed(full_run / "seed")
    assert summary["crossing"] == meta["crossing"] == summary["recorded_crossing"]
    out = capsys.readouterr().out
    assert "crossing rate per seed set in 8 fresh starts" in out and "recorded" in out
    assert _digest(full_run) == before


@pytest.mark.slow
def test_run_as_a_user_runs_it(tmp_path: Path, full_run: Path):
    """The script as a process, with its XLA flags (jaxais._speed: its CPU flags,
    which the in-process run has not): status 0, the same seed as the in-process run, nothing on
    stderr but the progress bar."""
    out = tmp_path / "run"
    env = script_env()
    cmd = [sys.executable, str(SCRIPT), *TINY_ARGS, "--generations", "3", "--out", str(out)]
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "error" not in proc.stderr.lower() and "Traceback" not in proc.stderr
    assert proc.stdout.startswith("3 generations in ") and str(out / "seed") in proc.stdout
    assert "crossing rate per seed set in 8 fresh starts" in proc.stdout
    assert_same_arrays(seed_arrays(out / "seed"), seed_arrays(full_run / "seed"))


@pytest.mark.slow
def test_same_seed_same_files(tmp_path: Path, monkeypatch, full_run: Path):
    # The same command line (relative --out) twice: identical seed.json and seed arrays.
    monkeypatch.chdir(tmp_path)
    runs = []
    for name in ("a", "b"):
        run_main("--generations", "3", "--out", "run")
        Path("run").rename(name)
        runs.append(tmp_path / name)
    a, b = runs
    assert (a / "seed" / "seed.json").read_bytes() == (b / "seed" / "seed.json").read_bytes()
    assert_same_arrays(seed_arrays(a / "seed"), seed_arrays(b / "seed"))
    sa, sb = (json.loads((d / "summary.json").read_text()) for d in runs)
    assert without_times(sa) == without_times(sb)
    # ... and the same numbers as the same run written elsewhere.
    assert_same_arrays(seed_arrays(a / "seed"), seed_arrays(full_run / "seed"))


@pytest.mark.slow
def test_resume_equals_uninterrupted(tmp_path: Path, full_run: Path):
    out = tmp_path / "run"
    run_main("--generations", "1", "--out", str(out))
    summary = run_main("--generations", "3", "--out", str(out), "--resume")
    assert summary["resumed_from_generation"] == 1
    assert_same_arrays(seed_arrays(out / "seed"), seed_arrays(full_run / "seed"))
    full = json.loads((full_run / "summary.json").read_text())
    assert without_times(summary["generations"]) == without_times(full["generations"])
    a, b = final_checkpoint(out, 3), final_checkpoint(full_run, 3)
    from test_checkpointing import assert_same_state

    assert_same_state(a, b)


@pytest.mark.slow
def test_interrupted_run_resumes_exactly(tmp_path: Path, full_run: Path):
    """A real SIGTERM during generation 1 (after checkpoint 1) ends the script process at once
    with its one line and status 143, leaving no seed or summary; resuming then gives the
    uninterrupted run's seed."""
    out = tmp_path / "run"
    code = f"""
import os, signal, sys
from jaxais.cli import run_script
from jaxais.ga import driver
from jaxais.scripts import evolve
sys.argv = ["evolve.py", *{[*TINY_ARGS, "--generations", "3", "--out", str(out)]!r}]
real_step, calls = driver.step, []
def step_then_sigterm(*args, **kwargs):
    calls.append(1)
    if len(calls) == 2:
        os.kill(os.getpid(), signal.SIGTERM)
    return real_step(*args, **kwargs)
driver.step = step_then_sigterm
run_script(evolve.main)
"""
    proc = run_python(code, timeout=300)
    assert proc.returncode == 143, proc.stderr[-3000:]
    assert "Traceback" not in proc.stderr
    assert proc.stderr.strip().splitlines()[-1] == "evolve.py: error: terminated"
    assert not (out / "seed").exists() and not (out / "summary.json").exists()
    run_main("--generations", "3", "--out", str(out), "--resume")
    assert_same_arrays(seed_arrays(out / "seed"), seed_arrays(full_run / "seed"))


# ------------------------------------------------------------------------------- errors


@pytest.mark.slow
def test_resume_refusals(tmp_path: Path, capsys, full_run: Path):
    last = expect_exit(capsys, "--out", str(tmp_path / "none"), "--resume")
    assert "no complete checkpoint" in last
    assert not (tmp_path / "none").exists()
    last = expect_exit(capsys, "--out", str(full_run), "--resume", "--mutation", "0.1")
    assert "different arguments" in last and "mutation" in last
    # The library call with other operators than the run's (examples/tournament_ga.py's).
    config = ga.GAConfig(**{**TINY.to_dict(), "generations": 3})
    ops = ga.default_operators(config).replace(mutation=ga.resample_mutation(0.5))
    with pytest.raises(ValueError) as info:
        evolution.evolve(full_run, config=config, resume=True, operators=ops)
    assert (
        str(info.value) == "--resume: this run used mutation 'resample(0.05)', not 'resample(0.5)'"
    )
    last = expect_exit(capsys, "--out", str(full_run), "--resume", "--generations", "2")
    assert "generation 3" in last
    last = expect_exit(capsys, "--out", str(full_run), "--generations", "3")
    assert "--resume" in last


def _digest(d: Path) -> dict[str, str]:
    return {
        str(p.relative_to(d)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(d.rglob("*"))
        if p.is_file()
    }


def test_corrupt_checkpoint_keeps_outputs(tmp_path: Path, capsys):
    out = tmp_path / "run"
    run_main("--generations", "2", "--out", str(out))
    for f in (out / "checkpoints" / "2").rglob("*"):
        if f.is_file() and f.parent.name == "d":
            f.write_bytes(f.read_bytes()[:5])
    before = _digest(out)
    last = expect_exit(capsys, "--generations", "3", "--out", str(out), "--resume")
    assert "corrupt checkpoint" in last
    assert _digest(out) == before  # nothing written, nothing lost


def _kept_outputs(tmp_path: Path) -> Path:
    keep = tmp_path / "kept"
    keep.mkdir()
    (keep / "summary.json").write_text('{"earlier": true}\n')
    (keep / "seed").mkdir()
    (keep / "seed" / "seed.json").write_text("{}\n")
    return keep


def test_bad_flags_subprocess(tmp_path: Path):
    """Each bad flag: exit status 2, exactly one line on stderr, no traceback, nothing written."""
    cases = [["--robots", "1"], ["--mutation", "1.5"], ["--generations", "0"], ["--world", "nope"]]
    keep = _kept_outputs(tmp_path)
    before = _digest(keep)
    env = {**os.environ, "JAXAIS_DEBUG": ""}
    # In parallel: each process pays for importing JAX, nothing more.
    procs = [
        subprocess.Popen(
            [sys.executable, str(SCRIPT), *case, "--out", str(keep)],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=env,
        )
        for case in cases
    ]
    for case, proc in zip(cases, procs, strict=True):
        _, err = proc.communicate(timeout=120)
        assert proc.returncode == 2, (case, err)
        lines = err.strip().splitlines()
        assert len(lines) == 1 and "Traceback" not in err, (case, err)
        assert lines[0].startswith("evolve.py: error: "), (case, err)
        assert case[1 if case[0] == "--world" else 0] in lines[0], (case, err)
    assert _digest(keep) == before


@pytest.mark.parametrize(
    "case",
    [
        ["--populations", "0"],
        ["--tau-cap", "-5"],
        ["--collision-cap", "0"],
        ["--elitism", "10"],
        ["--target-f", "nan"],
        ["--seed", "-1"],
        ["--robots", "many"],
        ["--no-such-flag"],
        ["--diversity", "--diversity-seeds", "1"],
        ["--diversity-seeds", "4"],  # without --diversity: ignored before
        ["--starts", "0"],
        ["--success-starts", "-1"],
        ["--success-starts", "0"],  # the default success rate needs checks
        ["--success-rate", "1.5"],
        ["--success-rate", "often"],
        ["--crossing-starts", "0"],
    ],
)
def test_bad_flags(tmp_path: Path, capsys, case: list[str]):
    """The same contract in this process, for the other flags (argparse's errors included)."""
    keep = _kept_outputs(tmp_path)
    before = _digest(keep)
    capsys.readouterr()
    with pytest.raises(SystemExit) as info:
        evolve.run([*case, "--out", str(keep)])
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert err.startswith("evolve.py: error: ") and (case[0] in err or case[1] in err)
    assert _digest(keep) == before


@pytest.mark.slow
def test_check_seed_and_out_refusals(tmp_path: Path, capsys, full_run: Path):
    last = expect_exit(capsys, "--check-seed", str(full_run / "seed"), "--out", str(tmp_path))
    assert "--check-seed" in last and "--out" in last
    capsys.readouterr()
    with pytest.raises(SystemExit) as info:
        evolve.run(["--populations", "2"])
    assert info.value.code == 2
    assert "--out" in capsys.readouterr().err
    with pytest.raises(SystemExit) as info:
        evolve.run(["--check-seed", str(tmp_path / "none")])
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "no such seed directory" in err


@pytest.mark.slow
def test_diversity_comparison(tmp_path: Path):
    summary = run_main(
        "--generations", "1", "--out", str(tmp_path / "d"), "--diversity", "--diversity-seeds", "2"
    )  # fmt: skip
    div = summary["diversity_comparison"]
    assert div["seeds"] == [0, 1]
    assert div["single"]["robots"] == 8 and len(div["multi"]["diversity"]) == 2
    assert set(div["welch_t"]) == {"statistic", "p_value"}
    assert 0.0 <= summary["seed_diversity"] <= 1.0
