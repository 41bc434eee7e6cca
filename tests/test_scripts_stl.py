"""scripts/trials.py and scripts/reproduce.py as a user runs them: subprocesses from the repo root.

Each real run pays JAX's start-up and a full compile, so the module starts the few runs it needs
at once (in a module fixture) and the tests read their outputs: one tiny ``trials.py`` run with
``--plot`` on two devices (filling a compilation cache of its own), the same on one device, and one
tiny ``reproduce.py`` run. Flag errors that answer before JAX loads run as processes (cheap);
mistakes answered after it run through the script's ``main`` here (``_python.call_main``).
"""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import _stl_fixtures as F
import pytest
from _python import TEST_XLA_FLAGS, call_main, run_python, start_script

from jaxais.systems import LABELS
from jaxais.trials import summarise

ROOT = Path(__file__).resolve().parent.parent
TIMEOUT = 480
RECORD_KEYS = {
    "tau",
    "collisions",
    "collisions_capped",
    "fitness",
    "failed",
    "failed_collisions",
    "failed_time",
    "failed_by",
    "trapped_s",
    "locked_s",
    "idiotypic_difference_rate",
    "iterations",
}
SUMMARY_KEYS = {
    "n",
    "tau",
    "collisions",
    "fitness",
    "failure_rate",
    "failed_by_collisions",
    "failed_by_time",
    "trapped_s",
    "locked_s",
    "idiotypic_difference_rate",
}


TWO_DEVICES = {"XLA_FLAGS": f"{TEST_XLA_FLAGS} --xla_force_host_platform_device_count=2"}
"""Two CPU devices, over which a script's batch is sharded (the scripts make one per core)."""
ONE_DEVICE = {"XLA_FLAGS": f"{TEST_XLA_FLAGS} --xla_force_host_platform_device_count=1"}


def _finish(proc: subprocess.Popen) -> subprocess.CompletedProcess:
    out, err = proc.communicate(timeout=TIMEOUT)
    return subprocess.CompletedProcess(proc.args, proc.returncode, out, err)


def _ok(proc: subprocess.CompletedProcess) -> None:
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "Traceback" not in proc.stderr


def assert_user_error(proc: subprocess.CompletedProcess, prog: str, *words: str) -> None:
    """Exit status 2, exactly one line on stderr, ``{prog}: error: ...``, no traceback."""
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith(f"{prog}: error: "), lines[0]
    for w in words:
        assert w in lines[0], (w, lines[0])


CONTENDER = "BV=examples/braitenberg.py:braitenberg"  # a controller written outside the library
CORRIDOR = "examples/worlds/corridor.toml"  # a world written outside the library


def _reproduce_args(seeds: Path) -> tuple:
    """reproduce.py's tiny run, with a contender (the last two words) beside the baseline."""
    return ("reproduce.py", "--trials", 2, "--tau-cap", 10, "--worlds", "world1",
            "--seeds", seeds, "--contender", CONTENDER)  # fmt: skip


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, object]:
    base = tmp_path_factory.mktemp("scripts")
    seeds = F.write_seed(base / "ltl" / "seed", seed=11)
    cache = {"JAXAIS_CACHE_DIR": str(base / "jax_cache")}
    out = base / "trials"
    out.mkdir()
    # 3 trials on 2 CPU devices: the batch is padded to 4 and sharded (jaxais.runner.rollout).
    trials_args = (
        "--system", "HDC", "--world", "world1", "--trials", 3, "--tau-cap", 10,
        "--out", out / "results.json", "--plot", out / "plot.png",
    )  # fmt: skip
    one_device = out / "one_device"
    one_device.mkdir()
    one_args = (*trials_args[:-4], "--out", one_device / "results.json")
    rep_dir, plain_dir = base / "reproduce", base / "plain"
    rep = start_script(*_reproduce_args(seeds), "--out", rep_dir)
    # The paper's systems alone: their records must not move with contenders beside them.
    # ... and a user's world file beside them, under the simulated worlds' protocol.
    plain = start_script(
        *_reproduce_args(seeds)[:-2], "--no-baseline", "--out", plain_dir,
        "--worlds", f"world1,{CORRIDOR}",
    )  # fmt: skip
    contender = start_script(
        "trials.py", "--contender", CONTENDER, "--trials", 2, "--tau-cap", 10,
        "--out", out / "contender.json",
    )  # fmt: skip
    single = start_script("trials.py", *one_args, JAXAIS_CACHE_DIR="off", **ONE_DEVICE)
    # The contender's own file, run as a user runs it (its --tiny, as CI runs every example).
    example = start_script("../examples/braitenberg.py", "--tiny")
    first = _finish(start_script("trials.py", *trials_args, **cache, **TWO_DEVICES))
    return {
        "one_device": _finish(single),
        "one_device_json": one_device / "results.json",
        "trials_dir": out,
        "first": first,
        "cached": sorted(p.name.split("-")[0] for p in (base / "jax_cache").iterdir()),
        "reproduce": _finish(rep),
        "reproduce_dir": rep_dir,
        "plain": _finish(plain),
        "plain_dir": plain_dir,
        "contender": _finish(contender),
        "example": _finish(example),
        "seeds": seeds,
    }


# ---------------------------------------------------------------------------------- trials.py


@pytest.mark.slow
def test_trials_script_writes_results_json(runs):
    proc = runs["first"]
    _ok(proc)
    doc = json.loads((runs["trials_dir"] / "results.json").read_text())
    assert {"system", "world", "random_set", "seed", "config", "trials", "summary"} <= set(doc)
    assert (doc["system"], doc["world"], doc["random_set"], doc["seed"]) == (
        "HDC",
        "world1",
        None,
        0,
    )
    assert doc["config"]["episode"]["tau_cap"] == 10.0
    assert doc["config"]["episode"]["collision_cap"] == 100
    assert doc["config"]["network"]["idiotope_period"] == 120
    assert len(doc["trials"]) == 3
    for rec in doc["trials"]:
        assert set(rec) >= RECORD_KEYS
        assert 0 < rec["tau"] <= 10.0 and rec["iterations"] <= 313
        assert rec["fitness"] == pytest.approx((8 * rec["collisions_capped"] + rec["tau"]) / 2)
        assert rec["failed"] == bool(rec["failed_by"])
        assert rec["idiotypic_difference_rate"] is None  # HDC is not idiotypic
    assert set(doc["summary"]) == SUMMARY_KEYS
    assert doc["summary"] == pytest.approx(summarise(doc["trials"]))
    assert "HDC in world1: 3 trials" in proc.stdout


@pytest.mark.slow
def test_trials_script_same_results_on_one_and_two_devices(runs):
    # Sharded over 2 CPU devices (padded from 3 runs to 4, recorded for --plot) or on one (the
    # refilling pool): the same document but for the command and the recording.
    _ok(runs["one_device"])
    sharded = json.loads((runs["trials_dir"] / "results.json").read_text())
    single = json.loads(runs["one_device_json"].read_text())
    assert len(single["trials"]) == 3 and sharded["config"]["episode"]["record"]
    for doc in (sharded, single):
        del doc["config"]["command"], doc["config"]["episode"]["record"]
    assert single == sharded


@pytest.mark.slow
def test_trials_script_fills_its_compilation_cache(runs):
    # JAXAIS_CACHE_DIR: the run stored its task-loop programs for the next one.
    assert {"jit__start", "jit__advance"} <= set(runs["cached"])


@pytest.mark.slow
def test_trials_script_plot_is_a_png(runs):
    data = (runs["trials_dir"] / "plot.png").read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 2000


def test_trials_script_user_errors(tmp_path: Path):
    """Each: exit status 2, one line on stderr, no traceback, no output file."""
    out = tmp_path / "r.json"
    cases = [
        (["--system", "HDC", "--world", "no_such_world"], ["no_such_world"]),
        (["--system", "SIE", "--seeds", tmp_path / "no_seed"], ["no_seed", "seed"]),
        (["--system", "HDC", "--trials", "0"], ["--trials"]),
        (["--system", "HDC", "--seeds", tmp_path], ["--seeds"]),
        (["--system", "SIE", "--random-set", "R2"], ["--random-set"]),
    ]
    for args, words in cases:
        assert_user_error(call_main("trials.py", *args, "--out", out), "trials.py", *words)
    bad_suffix = call_main("trials.py", "--system", "HDC", "--out", tmp_path / "r.txt")
    assert_user_error(bad_suffix, "trials.py", ".json")
    assert not out.exists() and not (tmp_path / "r.txt").exists()


@pytest.mark.parametrize(
    ("script", "args"),
    [
        ("trials.py", ["--system", "XYZ", "--out", "r.json"]),
        ("trials.py", ["--system", "HDC", "--trials", "many", "--out", "r.json"]),
        ("reproduce.py", ["--trials", "x", "--out", "d"]),
    ],
    ids=["trials-unknown-system", "trials-bad-int", "reproduce-bad-int"],
)
def test_argparse_errors_are_one_line(script, args, tmp_path):
    proc = _finish(
        start_script(script, *[tmp_path / a if a in ("r.json", "d") else a for a in args])
    )
    assert_user_error(proc, script)


# ---------------------------------------------------------------------------------- the library


def test_library_calls_check_their_arguments_before_jax_starts(tmp_path: Path):
    """jaxais.experiments.trials and .reproduce (what the scripts call) answer a bad argument
    with a one-line ValueError, before JAX loads and before anything is written."""
    out = tmp_path / "out"
    cases = [
        ("trials", ("HDC", out / "r.json"), {"trials": 0}, "--trials must be >= 1, got 0"),
        ("trials", ("HDC", out / "r.json"), {"seed": -1}, "--seed must be in [0, 2**32), got -1"),
        ("trials", ("HDC", tmp_path / "r.txt"), {}, "r.txt: expected a file name ending in .json"),
        ("trials", ("HDC", out / "r.json"), {}, "out: directory does not exist"),
        ("trials", ("XYZ",), {}, "unknown system 'XYZ'"),
        ("trials", ("SIE",), {"random_set": "R2"}, "--random-set applies to UIE and URL only"),
        ("reproduce", (out,), {"worlds": ["mars"]}, "--worlds: unknown world(s) ['mars']"),
        ("reproduce", (out,), {"trials": 1}, "--trials must be >= 2"),
        ("reproduce", (out,), {"tau_cap": 0}, "--tau-cap must be in (0, 1e6]"),
        ("trials", ("HDC",), {"tau_cap": 2e6}, "--tau-cap must be in (0, 1e6]"),
        ("reproduce", (out,), {"evolve": True, "seeds": "s"}, "exclude each other"),
        # Silently run before: a world twice, an LTL generation cap with no LTL run.
        ("reproduce", (out,), {"worlds": "real,real"}, "--worlds names a world twice: real,real"),
        ("reproduce", (out,), {"generations": 3}, "--generations caps the LTL run of --evolve"),
        # Grew until the kernel killed them, with no message.
        ("trials", ("HDC", out / "r.json"), {"trials": 10**8}, "--trials 100000000 needs about"),
        ("trials", ("HDC",), {"trials": 10**5, "plot": "p.png"}, "--trials 100000 needs about"),
        ("reproduce", (out,), {"trials": 10**8}, "--trials 100000000 needs about"),
    ]
    code = (
        "import sys\n"
        "import jaxais.experiments as x\n"
        f"for name, args, kw in {[(n, tuple(map(str, a)), kw) for n, a, kw, _ in cases]!r}:\n"
        "    try:\n"
        "        getattr(x, name)(*args, **kw)\n"
        "    except ValueError as err:\n"
        "        print(err)\n"
        "print('jax' in sys.modules)\n"
    )
    proc = run_python(code)
    assert proc.returncode == 0, proc.stderr[-2000:]
    lines = proc.stdout.splitlines()
    assert len(lines) == len(cases) + 1 and lines[-1] == "False", proc.stdout
    for line, (*_, message) in zip(lines, cases, strict=False):
        assert message in line, (message, line)
    assert not out.exists()


# ---------------------------------------------------------------------------------- reproduce.py


@pytest.mark.slow
def test_reproduce_end_to_end(runs):
    proc, out = runs["reproduce"], runs["reproduce_dir"]
    _ok(proc)
    tables = json.loads((out / "tables.json").read_text())
    assert {"table3", "table4", "table5", "idiotypic_difference_rate", "hypotheses"} <= set(tables)
    assert set(tables["hypotheses"]) == {"H1", "H2", "H3", "H4"}
    for verdict in tables["hypotheses"].values():
        assert isinstance(verdict["supported"], bool)
    report = (out / "report.md").read_text()
    assert len(report) > 500 and "H1" in report
    figures = sorted(p.name for p in (out / "figures").iterdir())
    assert figures and all(name.endswith(".png") for name in figures)
    for name in figures:
        assert name in report  # every figure is shown in the report
    trial_files = sorted(p.name for p in (out / "trials").iterdir())
    want = [f"world1_{label}.json" for label in (*LABELS, "NN", "BV")]
    want += ["world1_SIE_hold1.json"]
    want += ["world1_examples.npz"]  # the drawn trials: the world's unit, kept for --resume
    assert trial_files == sorted(want)
    # SIE with a selection every iteration: the calibration point, beside the paper's 20 %.
    hold1 = json.loads((out / "trials" / "world1_SIE_hold1.json").read_text())
    assert hold1["label"] == "SIE@hold=1" and hold1["config"]["readings"]["hold"] == 1
    assert all(r["idiotypic_difference_rate"] is not None for r in hold1["trials"])
    cal = tables["calibration"]
    assert (cal["k1"], cal["k2"], cal["paper_percent"]) == (0.85, 1.1, 20)
    assert set(cal["worlds"]["world1"]) == {"default", "hold=1"}
    assert "### The calibration point" in report and "### Lock-ups" in report
    # The shipped neural baseline (the contender NN) and a contender from a user's file ran
    # beside SIE and HDC, under the same protocol.
    nn = json.loads((out / "trials" / "world1_NN.json").read_text())
    assert len(nn["trials"]) == 2 and nn["config"]["episode"]["tau_cap"] == 10.0
    assert nn["config"]["contender"]["made_by"]["config"]["hidden"] > 0
    bv = json.loads((out / "trials" / "world1_BV.json").read_text())
    assert bv["label"] == "BV" and len(bv["trials"]) == 2
    source = bv["config"]["contender"]
    assert source["spec"] == CONTENDER and len(source["sha256"]) == 64
    assert list(tables["contenders"]["table3"]["world1"]) == ["SIE", "HDC", "NN", "BV"]
    assert set(tables["contenders"]["table4"]["world1"]) == {
        f"{c} vs {o}" for c in ("NN", "BV") for o in ("SIE", "HDC")
    }
    assert "## Beyond the paper" in report and "- **BV**: A Braitenberg-style vehicle" in report
    assert json.loads((out / "run.json").read_text())["contenders"]["BV"] == source
    for label in LABELS:
        doc = json.loads((out / "trials" / f"world1_{label}.json").read_text())
        assert doc["label"] == label and len(doc["trials"]) == 2
        assert doc["config"]["episode"]["tau_cap"] == 10.0
        idiotypic = label.startswith(("SIE", "UIE"))
        rates = [r["idiotypic_difference_rate"] for r in doc["trials"]]
        assert all((r is not None) == idiotypic for r in rates), (label, rates)
    run = json.loads((out / "run.json").read_text())
    assert run["ltl_seed"]["path"] == "seed" and run["trials"] == 2
    assert set(run["versions"]) >= {"jax", "jaxlib", "numpy"}
    # The records name no directory of the machine that made them.
    for doc in [out / "run.json", *(out / "trials").glob("*.json")]:
        assert str(runs["seeds"].parent) not in doc.read_text(), doc.name
    assert "Report:" in proc.stdout


@pytest.mark.slow
def test_contenders_leave_the_papers_records_bit_for_bit(runs):
    """The paper's systems' trials and tables are the same, value for value, with the neural
    baseline and a user's contender beside them and without (and another world after them)."""
    _ok(runs["plain"])
    with_, without = runs["reproduce_dir"], runs["plain_dir"]
    for label in (*LABELS, "SIE_hold1"):
        a, b = (
            json.loads((d / "trials" / f"world1_{label}.json").read_text())
            for d in (with_, without)
        )
        assert a["trials"] == b["trials"] and a["summary"] == b["summary"], label
    tables = [json.loads((d / "tables.json").read_text()) for d in (with_, without)]
    assert "contenders" not in tables[1]
    del tables[0]["contenders"]
    assert tables[0]["table3"]["world1"] == tables[1]["table3"]["world1"]
    assert tables[0]["table4"]["world1"] == tables[1]["table4"]["world1"]


@pytest.mark.slow
def test_reproduce_runs_a_world_file_under_the_simulated_protocol(runs):
    """``--worlds world1,PATH.toml``: the file's world (by its name) gets every system with R1
    and R2, as a simulated world does, and its own tables and report rows."""
    out = runs["plain_dir"]
    labels = [json.loads(p.read_text())["label"] for p in (out / "trials").glob("corridor_*.json")]
    assert sorted(labels) == sorted([*LABELS, "SIE@hold=1"])
    tables = json.loads((out / "tables.json").read_text())
    assert list(tables["table3"]) == ["world1", "corridor"]
    assert set(tables["table3"]["corridor"]) == set(LABELS)
    run = json.loads((out / "run.json").read_text())
    assert run["worlds"]["corridor"]["world"] == {"name": "corridor", "source": CORRIDOR}
    assert "**corridor**" in (out / "report.md").read_text()


@pytest.mark.slow
def test_the_contender_example_runs_as_a_user_runs_it(runs):
    _ok(runs["example"])
    assert "BV in world1: 4 trials, mean tau" in runs["example"].stdout


@pytest.mark.slow
def test_trials_files_fit_the_shipped_schema(runs):
    import jsonschema

    from jaxais.experiments.schema import SCHEMAS

    shipped = json.loads((ROOT / "docs" / "schema" / SCHEMAS["trials"]).read_text())
    validator = jsonschema.Draft202012Validator(shipped)
    for name in ("results.json", "contender.json"):
        doc = json.loads((runs["trials_dir"] / name).read_text())
        assert not [e.message for e in validator.iter_errors(doc)], name


@pytest.mark.slow
def test_trials_script_runs_a_contender(runs):
    _ok(runs["contender"])
    doc = json.loads((runs["trials_dir"] / "contender.json").read_text())
    assert (doc["label"], doc["system"], doc["random_set"]) == ("BV", "BV", None)
    assert len(doc["trials"]) == 2 and "network" not in doc["config"]
    assert doc["config"]["contender"]["spec"] == CONTENDER
    assert doc["config"]["command"].startswith("trials.py --contender " + CONTENDER)
    assert "BV in world1: 2 trials" in runs["contender"].stdout


def test_contender_mistakes_are_one_line_before_any_trial(tmp_path: Path):
    """A missing file or name, a NAME of the wrong shape, a paper's label: exit status 2, one
    line, nothing written."""
    bad = tmp_path / "bad.py"
    bad.write_text("X = 3\ndef broken():\n    raise RuntimeError('no')\nimport nonexistent_mod\n")
    shape = tmp_path / "shape.py"
    shape.write_text("X = (1, 2)\n")
    out = tmp_path / "r.json"
    cases = [
        (f"{tmp_path}/none.py:x", ["no such file", "none.py"]),
        ("examples/braitenberg.py:nope", ["defines no 'nope'"]),
        (f"{shape}:X", ["NAME must be a (Controller, params) tuple", "got tuple"]),
        (f"{bad}:X", ["cannot load", "ModuleNotFoundError", "nonexistent_mod"]),
        ("SIE=examples/braitenberg.py:braitenberg", ["label 'SIE' is the paper's"]),
        ("braitenberg", ["write [LABEL=]FILE.py:NAME"]),
        ("no_such_module_x:thing", ["cannot load no_such_module_x"]),
    ]
    for spec, words in cases:
        proc = call_main("trials.py", "--contender", spec, "--trials", 2, "--out", out)
        assert_user_error(proc, "trials.py", *words)
    rep = call_main("reproduce.py", "--worlds", "world1", "--contender", f"{shape}:X",
                    "--out", tmp_path / "rep")  # fmt: skip
    assert_user_error(rep, "reproduce.py", "NAME must be a (Controller, params) tuple")
    twice = call_main("reproduce.py", "--contender", "NN=examples/braitenberg.py:braitenberg",
                      "--worlds", "world1", "--out", tmp_path / "rep")  # fmt: skip
    assert_user_error(twice, "reproduce.py", "label 'NN' is the neural baseline's")
    assert not out.exists() and not (tmp_path / "rep").exists()


def test_reproduce_user_errors(tmp_path: Path):
    out = tmp_path / "rep"
    cases = [
        (["--worlds", "mars"], ["--worlds"]),
        (["--trials", "1"], ["--trials"]),
        (["--tau-cap", "0"], ["--tau-cap"]),
        (["--baseline", tmp_path / "none", "--worlds", "world1"], ["--baseline", "none"]),
        (["--baseline", "", "--worlds", "world1"], ["--baseline: .: not a trained"]),  # not NN
    ]
    for args, words in cases:
        assert_user_error(call_main("reproduce.py", *args, "--out", out), "reproduce.py", *words)
    missing = call_main(
        "reproduce.py", "--worlds", "world1", "--seeds", tmp_path / "none", "--out", out
    )
    assert_user_error(missing, "reproduce.py", "no such seed directory")
    assert not (out / "tables.json").exists()


@pytest.mark.slow
def test_reproduce_killed_and_resumed_gives_the_uninterrupted_run(runs, tmp_path: Path):
    """Killed before its world ends (SIGKILL) and after (SIGTERM, while it makes the tables and
    report), each time resumed: the trials, tables and claims of the fixture's uninterrupted
    run, exactly. Another --trials, a fresh start into the folder and --resume on a folder with
    no run are refused in one line."""
    import signal

    import numpy as np
    from test_resume import kill_after

    ref, out = runs["reproduce_dir"], tmp_path / "rep"
    args = _reproduce_args(runs["seeds"])[1:]
    kill_after(start_script("reproduce.py", *args, "--out", out), out, 0, signal.SIGKILL)
    kill_after(
        start_script("reproduce.py", *args, "--out", out, "--resume"), out, 1, signal.SIGTERM
    )
    other = call_main("reproduce.py", "--trials", 3, *args[2:], "--out", out, "--resume")
    fresh = call_main("reproduce.py", *args, "--out", out)
    nothing = call_main("reproduce.py", *args, "--out", tmp_path / "none", "--resume")
    assert_user_error(other, "reproduce.py", f"--trials: the run in {out} has 2, not 3")
    assert_user_error(fresh, "reproduce.py", f"{out} holds a partial reproduce run")
    assert_user_error(nothing, "reproduce.py", "none: no run to resume")
    assert not (tmp_path / "none").exists()
    _ok(_finish(start_script("reproduce.py", *args, "--out", out, "--resume")))
    files = sorted(p.name for p in (ref / "trials").iterdir())
    assert sorted(p.name for p in (out / "trials").iterdir()) == files
    for name in ["tables.json", "claims.json", *(f"trials/{f}" for f in files if ".json" in f)]:
        assert (ref / name).read_text() == (out / name).read_text(), name
    examples = [np.load(d / "trials" / "world1_examples.npz") for d in (ref, out)]
    assert examples[0].files == examples[1].files
    assert all(np.array_equal(examples[0][k], examples[1][k]) for k in examples[0].files)
    assert json.loads((out / "manifest.json").read_text())["status"] == "complete"


def test_trials_script_bad_worlds_and_seeds_are_one_line(tmp_path: Path):
    """Worlds the simulator cannot run and seeds that would wrap: exit status 2, one line, no
    output file (before this, a crowded world ended in an AssertionError inside JAX)."""
    world1 = (ROOT / "envs" / "worlds" / "world1.toml").read_text()
    walls = "".join(
        f"[[walls]]\nfrom = [{0.1 + 0.005 * k:.3f}, 1.45]\nto = [{0.1 + 0.005 * k:.3f}, 1.5]\n"
        for k in range(200)
    )
    (tmp_path / "crowded.toml").write_text(world1 + walls)
    (tmp_path / "misspelt.toml").write_text(world1.replace("\n[[pillars]]\n", "\n[[pilars]]\n", 1))
    out = tmp_path / "r.json"
    cases = [
        (["--world", tmp_path / "crowded.toml"], ["has 215 surfaces", "at most 64"]),
        (["--world", tmp_path / "misspelt.toml"], ["'pilars': unknown table", "'pillars'"]),
        (["--seed", -1], ["--seed must be in [0, 2**32), got -1"]),
        (["--seed", 2**32], ["--seed must be in [0, 2**32), got 4294967296"]),
    ]
    for args, words in cases:
        proc = call_main(
            "trials.py", "--system", "HDC", "--trials", 2, "--tau-cap", 5, *args, "--out", out
        )
        assert_user_error(proc, "trials.py", *words)
    assert not out.exists()
