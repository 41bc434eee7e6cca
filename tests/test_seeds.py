"""The claims ledger across LTL seeds (``jaxais.experiments.seeds``, ``scripts/seeds.py``).

Nothing real runs: the summary is checked on hand-made documents shaped like reproduce.py's
tables.json and claims.json and evolve.py's seed.json and summary.json, against hand-worked
numbers; the ledger's resume logic with a fake runner that writes those documents where the
scripts would; the script's flag errors through its ``main`` (``_python.call_main``), which
stop before any run.
"""

from __future__ import annotations

import json
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from _python import call_main

from jaxais.experiments import seeds as S

WORLDS = ("world1", "real")
CLAIMS = {
    "world1/SIE-lowest-c": "In Simulated World 1, SIE has the lowest mean c.",
    "world1/SIE-no-failures": "In Simulated World 1, SIE never fails.",
    "real/SIE-lowest-f": "In the real world, SIE has the lowest mean f.",
    "H1": "Seeded systems beat unseeded ones.",
}
HELD = {
    0: {"world1/SIE-no-failures", "H1"},
    1: {"world1/SIE-no-failures", "real/SIE-lowest-f", "H1"},
    2: {"world1/SIE-no-failures"},
}
SUPPORTED = {0: {"H1"}, 1: {"H1", "H2"}, 2: set()}


def claims_doc(held: set[str]) -> dict:
    claims = [{"id": cid, "world": cid.split("/")[0], "text": text, "held": cid in held,
               "evidence": "..."} for cid, text in CLAIMS.items()]  # fmt: skip
    summary = {"reproduced": len(held), "total": len(CLAIMS), "evaluated": len(CLAIMS)}
    return {"summary": summary, "ci_summary": {}, "claims": claims}


def tables_doc(s: int, locked: bool = True) -> dict:
    labels = ("SIE", "SRL", "HDC")
    doc = {
        "table5": {
            w: {
                k: {"c": 0.0, "tau": 10.0 * s + i, "total": 10.0 * s + i}
                for i, k in enumerate(labels)
            }
            for w in WORLDS
        },  # fmt: skip
        "trapped_s": {w: {k: 100.0 + s for k in labels} for w in WORLDS},
        "idiotypic_difference_rate": {w: {"SIE": 0.05 * (s + 1), "SRL": None} for w in WORLDS},
        "hypotheses": {
            h: {"supported": h in SUPPORTED[s], "evidence": "..."} for h in ("H1", "H2", "H3", "H4")
        },  # fmt: skip
    }
    if locked:
        doc["locked_s"] = {w: {"SIE": 7.0 + s, "SRL": 3.0, "HDC": 1.0} for w in WORLDS}
    return doc


def ltl_docs(s: int) -> tuple[dict, dict]:
    seed = {"generations": 50 + s, "crossing": {"rate": [1.0, 0.98]}}
    summary = {"generations_run": 50 + s, "stopped_by": "success", "wall_time_total_s": 100.0 + s}
    return summary, seed


def documents(s: int) -> dict:
    summary, seed = ltl_docs(s)
    return {"tables": tables_doc(s, locked=s != 2), "claims": claims_doc(HELD[s]),
            "ltl_summary": summary, "ltl_seed": seed}  # fmt: skip


# ------------------------------------------------------------------------------- the summary


def test_summarise_counts_claims_and_hypotheses_over_seeds():
    doc = S.summarise({s: documents(s) for s in (2, 0, 1)})
    assert doc["format"] == "jaxais-seeds/1"
    assert (doc["complete"], doc["done"], doc["requested"]) == (True, 3, 3)
    assert doc["claims_held"] == {"median": 2, "min": 1, "max": 3, "of": 4}
    fractions = {cid: (c["held_on"], c["of"], c["fraction"]) for cid, c in doc["claims"].items()}
    assert fractions == {
        "world1/SIE-lowest-c": (0, 3, 0.0),
        "world1/SIE-no-failures": (3, 3, 1.0),
        "real/SIE-lowest-f": (1, 3, pytest.approx(1 / 3)),
        "H1": (2, 3, pytest.approx(2 / 3)),
    }
    assert doc["claims"]["H1"]["text"] == CLAIMS["H1"]
    hyps = {h: (v["held_on"], v["seeds"]) for h, v in doc["hypotheses"].items()}
    assert hyps == {"H1": (2, [0, 1]), "H2": (1, [1]), "H3": (0, []), "H4": (0, [])}
    row = doc["seeds"]["1"]
    assert (row["claims_held"], row["claims_total"]) == (3, 4)
    assert set(row["held"]) == HELD[1]
    assert row["hypotheses"] == {"H1": True, "H2": True, "H3": False, "H4": False}
    assert row["failure_pct"] == {w: {"SIE": 10.0, "SRL": 11.0} for w in WORLDS}
    assert row["locked_s"] == {w: {"SIE": 8.0, "SRL": 3.0} for w in WORLDS}
    assert row["trapped_s"] == {w: 101.0 for w in WORLDS}
    assert row["difference_rate"] == {w: pytest.approx(0.10) for w in WORLDS}
    assert row["ltl"] == {"generations": 51, "stopped_by": "success", "crossing_rate": [1.0, 0.98]}
    # locked_s is optional (a tables.json from before it existed).
    assert doc["seeds"]["2"]["locked_s"] == {w: {"SIE": None, "SRL": None} for w in WORLDS}
    json.dumps(doc, allow_nan=False)  # seeds.json is plain JSON


def test_summarise_partial_ledger_and_even_median():
    doc = S.summarise({s: documents(s) for s in (0, 2)}, requested=range(5))
    assert (doc["complete"], doc["done"], doc["requested"]) == (False, 2, 5)
    assert doc["claims_held"] == {"median": 1.5, "min": 1, "max": 2, "of": 4}
    assert doc["claims"]["H1"]["held_on"] == 1 and doc["claims"]["H1"]["of"] == 2
    assert S.headline(doc) == (
        "claims held: median 1.5 (range 1-2 of 4) over 2 seeds; H1 on 1 of 2, H2 on 0 of 2, "
        "H3 on 0 of 2, H4 on 0 of 2 (2 of 5 seeds done)"
    )
    empty = S.summarise({}, requested=[0, 1])
    assert (empty["done"], empty["complete"], empty["claims"]) == (0, False, {})
    assert "0 of 2 seeds done" in S.markdown(empty)


def test_markdown_tables():
    doc = S.summarise({s: documents(s) for s in (0, 1, 2)}) | {"command": "seeds.py --out x"}
    text = S.markdown(doc)
    assert "3 of 3 seeds done (complete)" in text
    assert "| seed | generations | claims held | H1 | H2 | H3 | H4 | fail % world1 |" in text
    # seed 1: 51 generations, 3 of 4, H1 H2; fail % SIE / SRL; lock-up s; SIE difference rate %.
    assert (
        "| 1 | 51 | 3 of 4 | ✓ | ✓ | ✗ | ✗ | 10 / 11 | 10 / 11 | 8 / 3 | 8 / 3 | 10.0 | 10.0 |"
        in text
    )
    assert "| 2 | 52 | 1 of 4 | ✗ | ✗ | ✗ | ✗ | 20 / 21 | 20 / 21 | – / – | – / – | 15.0 |" in text
    ranked = [line.split(" | ")[0][2:] for line in text.splitlines() if "| 3 of 3 |" in line
              or "| 2 of 3 |" in line or "| 1 of 3 |" in line or "| 0 of 3 |" in line]  # fmt: skip
    assert ranked == ["world1/SIE-no-failures", "H1", "real/SIE-lowest-f", "world1/SIE-lowest-c"]
    assert "H1: 2 of 3 seeds (0, 1); H2: 1 of 3 seeds (1); H3: 0 of 3 seeds (none)" in text
    assert "`seeds.py --out x`" in text


def test_ltl_state(tmp_path):
    assert S.ltl_state(tmp_path / "nothing") == "fresh"
    (tmp_path / "checkpoints" / "3.orbax-checkpoint-tmp").mkdir(parents=True)
    assert S.ltl_state(tmp_path) == "fresh"  # no complete checkpoint: evolve.py starts over
    (tmp_path / "checkpoints" / "2").mkdir()
    assert S.ltl_state(tmp_path) == "resume"
    (tmp_path / "seed").mkdir()
    (tmp_path / "seed" / "seed.json").write_text("{}")
    assert S.ltl_state(tmp_path) == "resume"  # evolve.py stopped before summary.json
    (tmp_path / "summary.json").write_text("{}")
    assert S.ltl_state(tmp_path) == "done"


# ------------------------------------------------------------------------------- the ledger


class FakeScripts:
    """A runner writing what evolve.py and reproduce.py would write; fails where told."""

    def __init__(self, fail: set[tuple[int, str]] = frozenset()):
        self.calls: list[tuple[str, int, list[str]]] = []
        self.fail = fail

    def __call__(self, cmd: list[str], log: Path | None) -> int:
        assert cmd[:2] == [sys.executable, "-m"]
        stage = {"jaxais.scripts.evolve": "LTL", "jaxais.scripts.reproduce": "STL"}[cmd[2]]
        out, s = Path(cmd[cmd.index("--out") + 1]), int(cmd[cmd.index("--seed") + 1])
        self.calls.append((stage, s, cmd[3:]))
        if (s, stage) in self.fail:
            out.mkdir(parents=True, exist_ok=True)
            (out / "half.json").write_text("{")
            return 1
        if stage == "LTL":
            summary, seed = ltl_docs(s)
            (out / "seed").mkdir(parents=True, exist_ok=True)
            (out / "seed" / "seed.json").write_text(json.dumps(seed))
            (out / "summary.json").write_text(json.dumps(summary))
        else:
            assert cmd[cmd.index("--seeds") + 1] == str(
                out.parent.parent / "ltl" / f"seed_{s}" / "seed"
            )
            assert "--no-baseline" in cmd
            assert out.is_dir() == ("--resume" in cmd)  # the ledger cleared it, or resumes it
            out.mkdir(parents=True, exist_ok=True)
            (out / "tables.json").write_text(json.dumps(tables_doc(s)))
            (out / "claims.json").write_text(json.dumps(claims_doc(HELD[s])))
            (out / "run.json").write_text(json.dumps({"versions": {"jax": "fake", "seed": s}}))
            (out / "report.md").write_text("# report\n")
        return 0

    def stages(self) -> list[tuple[str, int]]:
        return [(stage, s) for stage, s, _ in self.calls]


def ledger(out: Path, runner, **kw) -> dict:
    """The ledger one seed at a time (``jobs`` 1: the fake runner's calls in order)."""
    return S.ltl_ledger(out, runner=runner, progress=False, **{"jobs": 1} | kw)


def test_seeds_run_side_by_side_by_default_one_per_core(tmp_path, monkeypatch):
    import os

    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1, 2})
    assert S.default_jobs() == 3
    run = FakeScripts()
    S.ltl_ledger(tmp_path, seeds=[0, 1, 2], runner=run, progress=False)
    assert json.loads((tmp_path / "run.json").read_text())["jobs"] == 3
    assert sorted(run.stages()) == [(stage, s) for stage in ("LTL", "STL") for s in (0, 1, 2)]


def test_a_signal_that_ends_the_script_would_stop_the_ledgers_children(tmp_path):
    """While the ledger runs, the CLI's signal handler has its child-stopper to call
    (jaxais.io.ON_SIGNAL; tests/test_bad_inputs.py: the handler calls it); afterwards not."""
    from jaxais import io

    seen = []

    class Watching(FakeScripts):
        def __call__(self, cmd, log):
            seen.append([getattr(f, "__name__", "") for f in io.ON_SIGNAL])
            return super().__call__(cmd, log)

    before = list(io.ON_SIGNAL)
    ledger(tmp_path, Watching(), seeds=[0])
    assert seen == [["on_signal"], ["on_signal"]] and before == io.ON_SIGNAL


def test_ledger_runs_each_seed_once_and_writes_the_ledger(tmp_path):
    run = FakeScripts()
    doc = ledger(tmp_path, run, seeds=[0, 1], trials=4, command="seeds.py --out x")
    assert run.stages() == [("LTL", 0), ("STL", 0), ("LTL", 1), ("STL", 1)]
    assert run.calls[0][2] == ["--out", str(tmp_path / "ltl" / "seed_0"), "--seed", "0"]
    assert run.calls[1][2][-2:] == ["--trials", "4"]
    assert doc["complete"] and doc["claims_held"]["median"] == 2.5
    assert json.loads((tmp_path / "seeds.json").read_text()) == json.loads(json.dumps(doc))
    assert "2 of 2 seeds done (complete)" in (tmp_path / "seeds.md").read_text()
    rec = json.loads((tmp_path / "run.json").read_text())
    assert (rec["command"], rec["seeds"], rec["trials"]) == ("seeds.py --out x", [0, 1], 4)
    assert rec["versions"] == {"jax": "fake", "seed": 0}  # reproduce.py's, of the first seed
    assert rec["wall_s"]["1"]["ltl"] == 101.0 and rec["wall_s"]["1"]["stl"] >= 0
    again = FakeScripts()
    resumed = ledger(tmp_path, again, seeds=[0, 1], trials=4, command="seeds.py --out x",
                     resume=True)  # fmt: skip
    assert resumed == doc and again.calls == []  # done seeds are not rerun
    with pytest.raises(ValueError, match=r"--trials: the run in .* has 4, not 6; resume it with"):
        ledger(tmp_path, again, seeds=[0, 1], trials=6, resume=True)  # refused up front
    with pytest.raises(ValueError, match="holds a complete seeds run: remove it or give a fresh"):
        ledger(tmp_path, again, seeds=[0, 1], trials=4)
    assert again.calls == []


def test_ledger_runs_contenders_on_every_seed_and_refuses_a_changed_file(tmp_path):
    """``contenders``: each seed's reproduce.py gets the specs; the manifest records each file's
    sha256, so a resume with an edited file is refused in one line; a contender's f and its
    level against SIE land in the ledger."""
    mine = tmp_path / "mine.py"
    mine.write_text("X = 1\n")
    spec = f"BR={mine}:braitenberg"

    class WithContender(FakeScripts):
        def __call__(self, cmd, log):
            code = super().__call__(cmd, log)
            if cmd[2] == "jaxais.scripts.reproduce":
                out = Path(cmd[cmd.index("--out") + 1])
                tables = json.loads((out / "tables.json").read_text())
                tables["contenders"] = {
                    "contenders": {"BR": {"spec": spec}},
                    "table3": {w: {"BR": {"f": 123.0}} for w in WORLDS},
                    "table4": {w: {"BR vs SIE": {"f": 99}} for w in WORLDS},
                }
                (out / "tables.json").write_text(json.dumps(tables))
            return code

    run = WithContender()
    doc = ledger(tmp_path / "l", run, seeds=[0], contenders=[spec])
    assert run.calls[1][2][-2:] == ["--contender", spec]
    assert doc["seeds"]["0"]["contenders"]["BR"]["real"] == {"f": 123.0, "level_vs_SIE": 99}
    assert "| 0 | 123 (99) | 123 (99) |" in (tmp_path / "l" / "seeds.md").read_text()
    mine.write_text("X = 2\n")
    with pytest.raises(ValueError, match="--contenders: the run in"):
        ledger(tmp_path / "l", run, seeds=[0], contenders=[spec], resume=True)
    with pytest.raises(ValueError, match="no such file"):
        ledger(tmp_path / "m", run, seeds=[0], contenders=[f"{tmp_path}/none.py:x"])
    with pytest.raises(ValueError, match="label 'SIE' is the paper's"):
        ledger(tmp_path / "m", run, seeds=[0], contenders=[f"SIE={mine}:x"])


def test_versions_before_any_seed_is_done(tmp_path):
    versions = S._versions(tmp_path, [])
    assert versions["jax"] and versions["jaxais"] and versions["backend"] is None


def test_ledger_resumes_ltl_and_stl_and_reruns_an_stl_without_a_manifest(tmp_path):
    # seed 0: finished LTL, STL begun (its manifest); seed 1: checkpoints only; seed 2: STL with
    # report.md but no manifest (not reproduce.py's: removed).
    from jaxais.io import open_run

    open_run(tmp_path, "seeds", {"seeds": [0, 1, 2], "trials": None, "extra_args": []})
    open_run(tmp_path / "stl" / "seed_0", "reproduce", {})
    for s in (0, 2):
        out = str(tmp_path / "ltl" / f"seed_{s}")
        cmd = [sys.executable, "-m", "jaxais.scripts.evolve", "--out", out, "--seed", str(s)]
        FakeScripts()(cmd, None)
    (tmp_path / "ltl" / "seed_1" / "checkpoints" / "7").mkdir(parents=True)
    stl2 = tmp_path / "stl" / "seed_2"
    stl2.mkdir(parents=True)
    (stl2 / "report.md").write_text("old")
    (stl2 / "stale.json").write_text("{")
    run = FakeScripts()
    doc = ledger(tmp_path, run, seeds=[0, 1, 2], resume=True)
    assert run.stages() == [("STL", 0), ("LTL", 1), ("STL", 1), ("STL", 2)]
    assert run.calls[0][2][-1] == "--resume" and run.calls[1][2][-1] == "--resume"
    assert "--trials" not in run.calls[0][2] and "--resume" not in run.calls[3][2]
    assert not (stl2 / "stale.json").exists() and (stl2 / "report.md").read_text() == "# report\n"
    assert doc["done"] == 3


def test_failed_seed_names_it_and_keeps_earlier_seeds(tmp_path):
    run = FakeScripts(fail={(1, "STL")})
    with pytest.raises(S.SeedRunError, match=r"^seed 1: the STL \(scripts/reproduce.py\) failed"):
        ledger(tmp_path, run, seeds=[0, 1, 2])
    assert run.stages() == [("LTL", 0), ("STL", 0), ("LTL", 1), ("STL", 1)]  # seed 2 not begun
    doc = json.loads((tmp_path / "seeds.json").read_text())
    assert (doc["done"], doc["requested"], list(doc["seeds"])) == (1, 3, ["0"])
    assert json.loads((tmp_path / "run.json").read_text())["versions"] == {"jax": "fake", "seed": 0}
    assert "1 of 3 seeds done (partial" in (tmp_path / "seeds.md").read_text()
    rerun = FakeScripts()
    assert ledger(tmp_path, rerun, seeds=[0, 1, 2], resume=True)["complete"]
    assert rerun.stages() == [("STL", 1), ("LTL", 2), ("STL", 2)]
    assert not (tmp_path / "stl" / "seed_1" / "half.json").exists()


def test_failed_ltl_with_jobs_points_to_its_log(tmp_path):
    run = FakeScripts(fail={(0, "LTL")})
    with pytest.raises(S.SeedRunError, match=r"seed 0: the LTL .* see .*seed_0\.ltl\.log"):
        ledger(tmp_path, run, seeds=[0, 1], jobs=2)
    assert ("STL", 0) not in run.stages()


def test_ledger_argument_errors(tmp_path):
    run = FakeScripts()
    (tmp_path / "file").write_text("")
    for kw, match in [
        ({"seeds": []}, "at least one"),
        ({"seeds": [1, 1]}, "distinct"),
        ({"seeds": [-1]}, "integers in"),
        ({"trials": 1}, "trials must be >= 2"),
        ({"jobs": 0}, "jobs must be an integer >= 1"),
        ({"extra_args": ["--seed=3"]}, "extra_args may not set"),
        ({"out": tmp_path / "file"}, "file: not a directory"),
    ]:
        with pytest.raises(ValueError, match=match):
            S.ltl_ledger(**({"out": tmp_path / "x", "seeds": [0]} | kw), runner=run)
    assert run.calls == [] and not (tmp_path / "x").exists()


def test_the_ledgers_subprocesses_run_the_installed_scripts(tmp_path):
    # python -m jaxais.scripts.NAME: the package's scripts, found wherever jaxais is installed
    # (here from a folder outside the checkout).
    for name in ("evolve", "reproduce"):
        proc = subprocess.run([sys.executable, "-m", f"jaxais.scripts.{name}", "--help"],
                              cwd=tmp_path, capture_output=True, text=True, timeout=60)  # fmt: skip
        assert proc.returncode == 0 and f"usage: {name}.py" in proc.stdout, proc.stderr


def test_default_runner_logs_and_stops_children(tmp_path):
    procs = S._Processes()
    log = tmp_path / "logs" / "a.log"
    assert procs([sys.executable, "-c", "import sys; print('out'); print('err', file=sys.stderr)"],
                 log) == 0  # fmt: skip
    assert sorted(log.read_text().split()) == ["err", "out"]
    codes = []
    waiter = threading.Thread(
        target=lambda: codes.append(
            procs([sys.executable, "-c", "import time; time.sleep(60)"], None)
        )
    )
    waiter.start()
    deadline = time.monotonic() + 30
    while not procs._live and time.monotonic() < deadline:
        time.sleep(0.01)
    procs.stop()
    waiter.join(timeout=30)
    assert codes == [-15]  # SIGTERM
    assert procs(["true"], None) == -15  # nothing starts once stopped


# ------------------------------------------------------------------------------- the script


def test_script_flag_errors_are_one_line(tmp_path):
    a_file = tmp_path / "file"
    a_file.write_text("")
    out = ("--out", tmp_path / "o")
    cases = [
        ((*out, "--seeds", 0), "--seeds must be >= 1"),
        ((*out, "--jobs", 0), "--jobs must be an integer >= 1"),
        ((*out, "--trials", 1), "--trials must be >= 2"),
        ((*out, "--first", -1), "--first must be in"),
        ((*out, "--seeds", "x"), "invalid int value"),
        (("--out", a_file), "not a directory"),
        (("--out", a_file / "sub"), "Not a directory"),
    ]
    for args, match in cases:
        proc = call_main("seeds.py", *args)
        assert proc.returncode == 2, (args, proc.stderr)
        assert proc.stdout == "" and proc.stderr.count("\n") == 1, proc.stderr
        assert proc.stderr.startswith("seeds.py: error: ") and match in proc.stderr, proc.stderr
    assert not (tmp_path / "o").exists()


def test_a_damaged_results_file_of_a_done_seed_is_named(tmp_path):
    ledger(tmp_path, FakeScripts(), seeds=[0])
    (tmp_path / "stl" / "seed_0" / "tables.json").write_bytes(b"\x00\x9f not json")
    with pytest.raises(ValueError, match=r"seed_0/tables.json: missing or not JSON; use a fresh"):
        ledger(tmp_path, FakeScripts(), seeds=[0], resume=True)
