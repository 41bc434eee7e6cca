"""Issue 41: c under each counting rule, the world scale, the "why" of a failing claim and the
robustness map (``jaxais.experiments.robustness``, ``scripts/robustness.py``).

The map runs nothing real: a fake runner writes what evolve.py and reproduce.py would write
(claims.json with its ``by_rule``), so the cells, fractions, marginals, classes and resume are
checked against hand-worked values; the counting and the scaling against hand-made records and
world files.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import pytest
from _python import call_main

from jaxais.experiments import explanations, protocol, robustness, stats

# ------------------------------------------------------------------ c under each counting rule


def record(tau, episode, reading, entry=None, failed_time=False):
    capped = min(episode, 100)
    return {"tau": tau, "collisions": episode, "collisions_capped": capped,
            "collisions_episode": episode, "collisions_reading": reading,
            "collisions_entry": reading if entry is None else entry,
            "fitness": (8 * capped + tau) / 2, "failed": episode > 100 or failed_time,
            "failed_collisions": episode > 100, "failed_time": failed_time,
            "failed_by": ["time"] * failed_time}  # fmt: skip


def test_under_rule_recounts_c_f_and_the_collision_failures():
    results = {"world1": {"SIE": [record(100.0, 2, 150), record(4000.0, 1, 30, failed_time=True)]}}
    same = stats.under_rule(results, "episode")
    assert same == results  # the default: the records as they are
    view = stats.under_rule(results, "reading", cap=100)["world1"]["SIE"]
    # 150 readings: capped at 100, f = (8 * 100 + 100) / 2, failed on collisions (150 > 100).
    assert view[0] | {} == record(100.0, 2, 150) | {
        "collisions": 150, "collisions_capped": 100, "fitness": 450.0, "failed": True,
        "failed_collisions": True, "failed_by": ["collisions"]}  # fmt: skip
    assert (view[1]["fitness"], view[1]["failed_by"]) == ((8 * 30 + 4000.0) / 2, ["time"])
    assert stats.table5({"world1": {"SIE": view}})["world1"]["SIE"] == {
        "c": 50.0, "tau": 50.0, "total": 100.0}  # fmt: skip
    old = {"world1": {"SIE": [{k: v for k, v in record(1.0, 0, 0).items()
                               if k != "collisions_reading"}]}}  # fmt: skip
    with pytest.raises(ValueError, match="world1 SIE: a trial record without 'collisions_reading'"):
        stats.under_rule(old, "reading")
    assert not stats.has_rule(old, "reading") and stats.rule_tables(old) == {}
    with pytest.raises(ValueError, match="rule must be one of episode, reading"):
        stats.under_rule(results, "entry")


# ------------------------------------------------------------------------------ world scale


def test_scale_document_scales_places_and_obstacles_not_the_goal_or_heights():
    from jaxais.envs.world import scale_document

    doc = {"name": "w", "arena": {"width": 1.5, "height": 1.0, "wall_height": 0.1},
           "robot": {"start_region": [0.1, 0.1, 0.2, 0.2], "start_heading": [-1.0, 1.0]},
           "goal": {"shape": "box", "half_size": [0.05, 0.05], "height": 0.1,
                    "region": [0.5, 0.8, 1.0, 0.9]},
           "boxes": [{"center": [0.4, 0.4], "half_size": [0.1, 0.05], "height": 0.06}],
           "pillars": [{"center": [0.75, 0.5], "radius": 0.04}],
           "walls": [{"from": [0.0, 0.5], "to": [0.3, 0.5]}]}  # fmt: skip
    out = scale_document(doc, 2.0)
    assert out["arena"] == {"width": 3.0, "height": 2.0, "wall_height": 0.1}
    assert out["robot"] == {"start_region": [0.2, 0.2, 0.4, 0.4], "start_heading": [-1.0, 1.0]}
    assert out["goal"] == doc["goal"] | {"region": [1.0, 1.6, 2.0, 1.8]}
    assert out["boxes"] == [{"center": [0.8, 0.8], "half_size": [0.2, 0.1], "height": 0.06}]
    assert out["pillars"] == [{"center": [1.5, 1.0], "radius": 0.08}]
    assert out["walls"] == [{"from": [0.0, 1.0], "to": [0.6, 1.0]}]
    assert doc["arena"]["width"] == 1.5  # not changed


def test_scaled_world_and_camera():
    import numpy as np

    from jaxais import envs
    from jaxais.experiments.records import scaled_world

    one, p1 = scaled_world("world1", 1.0)
    two, p2 = scaled_world("world1", 2.0)
    np.testing.assert_allclose(two.arena, 2 * np.asarray(one.arena))
    np.testing.assert_allclose(two.pillar[:4], np.asarray(one.pillar[:4]) * 2, rtol=1e-6)
    np.testing.assert_array_equal(two.goal_half, one.goal_half)
    np.testing.assert_array_equal(two.box_height, one.box_height)
    assert (float(p1.camera_range), float(p2.camera_range)) == (2.0, 4.0)
    assert float(p2.body_radius) == float(p1.body_radius)
    with pytest.raises(envs.WorldError, match=r"arena.width.*\(at world scale 100\)"):
        envs.load_world("world1", scale=100.0)


@pytest.mark.parametrize(
    "value, worlds, message",
    [(0, (), "must be a finite number > 0, got 0"), (math.nan, (), "finite number > 0"),
     (math.inf, (), "finite number > 0"), ("2", (), "must be a number, got '2'"),
     (True, (), "must be a number"),
     (2.0, ("world1", "real"), "does not apply to real: the paper gives the real pen's size"),
     (2.0, ("ga_maze",), "does not apply to ga_maze")],
)  # fmt: skip
def test_check_world_scale_refuses_in_one_line(value, worlds, message):
    with pytest.raises(ValueError, match=message):
        protocol.check_world_scale(value, worlds)
    assert protocol.check_world_scale(1, ("real",)) == 1.0  # scale 1 is every world's own


@pytest.mark.parametrize(
    "args, message",
    [(("--world-scale", "0"), "argument --world-scale: must be a finite number > 0, got '0'"),
     (("--world-scale", "x"), "argument --world-scale: must be a number, got 'x'"),
     (("--world-scale", "2", "--world", "real"), "--world-scale does not apply to real")],
)  # fmt: skip
def test_trials_script_refuses_a_bad_world_scale(tmp_path, args, message):
    proc = call_main("trials.py", "--system", "SIE", "--out", tmp_path / "t.json", *args)
    assert proc.returncode == 2 and message in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1 and "Traceback" not in proc.stderr


# ------------------------------------------------------------------------------ why


def test_why_takes_the_first_that_applies(tmp_path):
    run = tmp_path / "big"
    run.mkdir()
    claims = [{"id": i, "held": h} for i, h in (("A", True), ("B", False), ("C", False))]
    (run / "claims.json").write_text(json.dumps({"claims": claims}))
    (run / "run.json").write_text(json.dumps({"trials": 1000}))
    ledger = tmp_path / "seeds.json"
    ledger.write_text(
        json.dumps(
            {
                "format": "jaxais-seeds/1",
                "claims": {
                    "A": {"held_on": 0, "of": 10},
                    "B": {"held_on": 3, "of": 10},
                    "C": {"held_on": 0, "of": 10},
                    "world2/SIE-lowest-c": {"held_on": 0, "of": 10},
                },
            }
        )
    )
    cell = lambda scale, rule, held: {"ltl_seed": 4, "trial_seed": 4, "scale": scale,
                                      "rule": rule, "claims": held}  # fmt: skip
    rob = tmp_path / "robustness.json"
    rob.write_text(json.dumps({"format": "jaxais-robustness/1", "cells": [
        cell(1.0, "episode", {"C": True}), cell(2.0, "reading", {"C": True}),
        cell(1.0, "reading", {"C": True}), cell(2.0, "episode", {"real/X": True, "world1/X": True}),
    ]}))  # fmt: skip
    ev = explanations.load([run, ledger, rob])
    why = lambda cid: explanations.why({"id": cid, "held": False}, ev)
    assert why("A") == "sample size: holds at n = 1000"
    assert why("B") == "seed-dependent: holds on 3 of 10 LTL seeds"
    assert why("C") == ("depends on an unstated choice: how a collision is counted (holds at LTL "
                        "seed 4, world scale 1, c per reading)")  # fmt: skip
    assert why("world2/SIE-lowest-c").startswith("not reproduced: our RL-only SRL collides less")
    assert why("world1/X") == ("depends on an unstated choice: the world scale (holds at LTL seed "
                               "4, world scale 2, c per contact episode)")  # fmt: skip
    # The real pen keeps its size at every scale: a cell at scale 2 is its world at ours.
    assert why("real/X") == "not reproduced (no mechanism measured)"
    assert why("Z") == "not reproduced (no mechanism measured)"
    assert explanations.why({"id": "B", "held": True}, ev) == ""
    assert explanations.why({"id": "B", "held": None}, ev) == ""
    with pytest.raises(ValueError, match="--explain .*seeds.json: a second jaxais-seeds/1"):
        explanations.load([ledger, ledger])
    (run / "run.json").write_text(json.dumps({"trials": None}))
    with pytest.raises(ValueError, match="needs a run of more than 30"):
        explanations.load([run])


def test_every_mechanism_names_its_source():
    for key, (sentence, source) in explanations.MECHANISMS.items():
        assert sentence and source and "docs/" in source or "issue" in source, key


# ------------------------------------------------------------------------------ the map


HELD = {  # (seed, scale, rule) -> the claims held
    (0, 1.0, "episode"): {"X"}, (0, 1.0, "reading"): {"X", "Y"},
    (0, 2.0, "episode"): {"X", "Y"}, (0, 2.0, "reading"): {"X", "Y"},
    (1, 1.0, "episode"): {"X"}, (1, 1.0, "reading"): set(),
    (1, 2.0, "episode"): {"X"}, (1, 2.0, "reading"): {"X"},
}  # fmt: skip


def claims_doc(s: int, k: float) -> dict:
    doc = lambda rule: {"claims": [{"id": i, "held": i in HELD[s, k, rule]} for i in "XYZ"]}
    return doc("episode") | {"by_rule": {"reading": doc("reading")}}


class FakeScripts:
    def __init__(self, stop_after: int | None = None):
        self.calls: list[tuple[str, list[str]]] = []
        self.stop_after = stop_after

    def __call__(self, cmd: list[str], log: Path | None) -> int:
        assert cmd[:2] == [sys.executable, "-m"]
        out = Path(cmd[cmd.index("--out") + 1])
        self.calls.append((cmd[2], cmd[3:]))
        if cmd[2] == "jaxais.scripts.evolve":
            (out / "seed").mkdir(parents=True)
            (out / "seed" / "seed.json").write_text("{}")
            (out / "summary.json").write_text("{}")
            return 0
        if self.stop_after is not None and sum(c[0].endswith("reproduce") for c in self.calls) > (
                self.stop_after):  # fmt: skip
            raise KeyboardInterrupt
        s = int(cmd[cmd.index("--seed") + 1])
        k = float(cmd[cmd.index("--world-scale") + 1]) if "--world-scale" in cmd else 1.0
        out.mkdir(parents=True, exist_ok=True)
        (out / "claims.json").write_text(json.dumps(claims_doc(s, k)))
        return 0


def test_the_map_cells_fractions_marginals_and_classes(tmp_path):
    run = FakeScripts()
    doc = robustness.run(tmp_path, [0, 1], runner=run, jobs=1, progress=False, trials=4)
    evolved = [c for c in run.calls if c[0] == "jaxais.scripts.evolve"]
    assert len(evolved) == 2  # one LTL per seed, for both scales
    stl = [c[1] for c in run.calls if c[0] == "jaxais.scripts.reproduce"]
    assert stl[1] == ["--seeds", str(tmp_path / "ltl" / "seed_0" / "seed"), "--out",
                      str(tmp_path / "stl" / "seed_0_scale_2"), "--seed", "0", "--no-baseline",
                      "--world-scale", "2", "--trials", "4"]  # fmt: skip
    assert len(doc["cells"]) == 8 and doc["complete"]
    assert doc["cells"][1] == {"ltl_seed": 0, "trial_seed": 0, "scale": 1.0, "rule": "reading",
                               "claims": {"X": True, "Y": True, "Z": False}}  # fmt: skip
    x, y, z = (doc["claims"][i] for i in "XYZ")
    assert (x["fraction"], x["class"]) == (7 / 8, "robust")
    assert (y["fraction"], y["class"]) == (3 / 8, "fragile")
    assert (z["fraction"], z["class"]) == (0.0, "never")
    # Y: over the scales with c per episode (seeds 0 and 1), over the rules at scale 1.
    assert y["marginals"] == {"ltl_seed": {"0": 0.0, "1": 0.0},
                              "scale": {"1": 0.0, "2": 0.5},
                              "rule": {"episode": 0.0, "reading": 0.5}}  # fmt: skip
    assert doc["classes"] == {"robust": 1, "fragile": 1, "never": 1}
    assert json.loads((tmp_path / "robustness.json").read_text())["format"] == "jaxais-robustness/1"
    assert "1 robust, 1 fragile, 1 never of 3 claims over 8 of 8 cells" in (
        tmp_path / "robustness.md").read_text()  # fmt: skip
    assert (tmp_path / "robustness.png").stat().st_size > 0
    rec = json.loads((tmp_path / "run.json").read_text())
    assert rec["cpu_s_total"] >= 0 and rec["wall_s_total"] > 0 and len(rec["wall_s"]) == 4


def test_the_map_resumes_to_the_uninterrupted_result(tmp_path):
    kw = {"jobs": 1, "progress": False, "command": "robustness.py --seeds 2"}
    whole = robustness.run(tmp_path / "a", [0, 1], runner=FakeScripts(), **kw)
    with pytest.raises(KeyboardInterrupt):
        robustness.run(tmp_path / "b", [0, 1], runner=FakeScripts(stop_after=2), **kw)
    partial = json.loads((tmp_path / "b" / "robustness.json").read_text())
    assert (partial["done"], partial["complete"]) == (4, False)
    again = FakeScripts()
    resumed = robustness.run(tmp_path / "b", [0, 1], runner=again, resume=True, **kw)
    assert resumed == whole
    assert [c[0] for c in again.calls] == ["jaxais.scripts.reproduce"] * 2  # the other two
    with pytest.raises(ValueError, match="--scales: the run in .* has"):
        robustness.run(tmp_path / "b", [0, 1], [1.0], runner=again, jobs=1, resume=True)


@pytest.mark.parametrize(
    "kw, message",
    [({"scales": [0.0]}, "--scales must be a finite number > 0"),
     ({"scales": [1.0, 1.0]}, "--scales must be distinct"),
     ({"rules": ["entry"]}, "--rules: one or more of episode, reading"),
     ({"seeds_": [1, 1]}, "--seeds must be distinct"), ({"trials": 1}, "--trials must be"),
     ({"jobs": 0}, "--jobs must be"), ({"extra_args": ["--world-scale=2"]}, "may not set")],
)  # fmt: skip
def test_the_map_refuses_bad_arguments_before_any_run(tmp_path, kw, message):
    with pytest.raises(ValueError, match=message):
        robustness.run(tmp_path, **{"seeds_": [0], "runner": FakeScripts(), "jobs": 1} | kw)
    assert not (tmp_path / "manifest.json").exists()


def test_the_report_gives_the_per_reading_figures_beside_ours(tmp_path):
    from jaxais.experiments import claims, report

    results = {"world1": {"SIE": [record(100.0, 1, 150), record(120.0, 2, 20)],
                          "SRL": [record(300.0, 0, 0), record(340.0, 1, 5)]}}  # fmt: skip
    tables = stats.build_tables(results) | {"by_rule": stats.rule_tables(results)}
    assert tables["by_rule"]["reading"]["table3"]["world1"]["SIE"]["c"] == 60.0  # (100 + 20) / 2
    by_rule = claims.by_rule(results)
    held = {c["id"]: c["held"] for c in by_rule["reading"]["claims"]}
    assert held["world1/SIE-lowest-c"] is False  # SIE's 60 per reading against SRL's 2.5
    rule_claims = {r: d["claims"] for r, d in by_rule.items()}
    text = report.write_report(tmp_path, tables, results, report.load_paper_tables(), None, {},
                               None, rule_claims=rule_claims).read_text()  # fmt: skip
    k = claims.summary(by_rule["reading"]["claims"])
    assert f"Counting c per reading (Vm ≥ 2400) instead: {k['reproduced']} of " in text
    assert "| Claim | The paper says | Held | Held, c per reading (Vm ≥ 2400) | Why" in text
    assert "| c per reading (Vm ≥ 2400), ours | f per reading (Vm ≥ 2400), ours |" in text
    assert "| Ours | Ours, c per reading (Vm ≥ 2400) | Paper |" in text
