"""Tests of jaxais.experiments.report: the packaged paper tables and the written report."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from _records import trial

from jaxais.experiments import claims, protocol, report, stats

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def paper() -> dict:
    return report.load_paper_tables()


def synthetic_results(paper: dict, n: int = 6) -> dict:
    """Trials scattered around the paper's Table 3 means; in world1 HDC is made far better than
    SRL (paper: SRL 679 < HDC 688) so the ordering of f differs there."""
    rng = np.random.default_rng(1)
    out = {}
    for world in protocol.WORLDS:
        out[world] = {}
        for s in protocol.systems_for_world(world):
            mean = dict(paper["table3"][world][s])
            if (world, s) == ("world1", "HDC"):
                mean = {"c": 1, "tau": 400}
            taus = np.clip(rng.normal(mean["tau"], 0.1 * mean["tau"], n), 10, 4000)
            rate = 0.2 if "IE" in s else None
            out[world][s] = [trial(t, int(mean["c"]), rate, 12.5) for t in taus]
    out["world1"]["URL-R1"][0] = trial(4000, 3000)  # failed by both caps
    return out


# --------------------------------------------------------------------------- paper tables


def test_paper_tables_spot_cells(paper):
    assert paper["table3"]["world1"]["SIE"] == {"c": 1, "tau": 562, "f": 284}
    assert paper["table3"]["real"]["HDC"] == {"c": 44, "tau": 1439, "f": 897}
    assert paper["table5"]["real"]["URL-R1"]["total"] == 100
    assert paper["table5"]["world2"]["UIE-R2"] == {"c": 43, "tau": 17, "total": 43}
    assert paper["table4"]["world1"]["SRL vs UIE-R1"] == {"c": 98, "tau": 49, "f": 72}
    assert paper["table4"]["world2"]["SIE vs HDC"]["c"] == 33
    assert paper["table5_mean"]["HDC"] == {"c": 3, "tau": 21, "total": 24}
    assert "ICARIS 2008" in paper["source"] and paper["notes"]


def test_paper_tables_layout(paper):
    for world in protocol.WORLDS:
        assert tuple(paper["table3"][world]) == protocol.systems_for_world(world)
        assert tuple(paper["table5"][world]) == protocol.systems_for_world(world)
        pairs = [f"{a} vs {b}" for a, b in stats.comparison_pairs(world)]
        assert list(paper["table4"][world]) == pairs
    # f is (8c + tau)/2 of the rounded means up to the rounding of c.
    for world, rows in paper["table3"].items():
        for row in rows.values():
            assert abs(row["f"] - (8 * row["c"] + row["tau"]) / 2) <= 2.5, world


# --------------------------------------------------------------------------- ordering


def test_ordering_differences():
    ours = {"world1": {"SIE": {"f": 10.2}, "SRL": {"f": 30.0}, "HDC": {"f": 20.0}}}
    paper = {"world1": {"SIE": {"f": 10}, "SRL": {"f": 20}, "HDC": {"f": 30}}}
    diffs = report.ordering_differences(ours, paper, ["f"])
    assert len(diffs) == 1
    d = diffs[0]
    assert d["systems"] == ["SRL", "HDC"]
    assert d["ours"] == {"SIE": 1, "SRL": 3, "HDC": 2}
    assert d["ours_order"] == "SIE < HDC < SRL"
    # Rounding to the paper's precision keeps ties: 2.4 and 2 are both "2".
    ours = {"world2": {"SIE": {"c": 2.4}, "HDC": {"c": 1.6}}}
    paper = {"world2": {"SIE": {"c": 2}, "HDC": {"c": 2}}}
    assert report.ordering_differences(ours, paper, ["c"]) == []


# --------------------------------------------------------------------------- report


def test_write_report_full(tmp_path, paper):
    results = synthetic_results(paper)
    tables = stats.build_tables(results)
    ltl = {  # as evolve.py writes it: per population, then per generation
        "wall_time_s": 12.5,
        "populations": [{"best_f_generation_0": 300, "best_f_final_generation": 297}] * 5,
        "generations": [
            {"generation": g, "populations": [{"best_f": 300 - g, "mean_f": 400 - g}] * 5}
            for g in range(4)
        ],
    }
    trajectories = {
        w: {s: np.cumsum(np.ones((20, 2)), axis=0) for s in protocol.systems_for_world(w)}
        for w in ("world1", "real")
    }
    drawn = []
    path = report.write_report(
        tmp_path,
        tables,
        results,
        paper,
        ltl,
        {"seed": 3, "trials": 6},
        {"ltl_s": 1.5, "stl": {"world1_s": 0.25}},
        trajectories,
        lambda ax, world: drawn.append(world),
    )
    assert path == tmp_path / "report.md"
    text = path.read_text()
    lines = text.splitlines()
    ledger = claims.claims(results)
    counts = claims.summary(ledger)
    assert counts["total"] == counts["evaluated"] == 32
    # The ledger line opens the report, right after the title, then the line of the interval
    # readings, then the table of claims.
    assert lines[0].startswith("# ") and lines[1] == ""
    assert lines[2] == f"**{counts['reproduced']} of 32 of the paper's claims reproduced**"
    assert lines[4] == claims.ci_headline(claims.ci_summary(ledger))
    # Then what does not reproduce, plainly: here (the fake tables) H3 alone.
    assert lines[6] == (
        "**What does not reproduce.** H3 is not supported (the idiotypic network does not beat "
        "the hand-designed controller in every world)."
    )
    assert lines[8] == (
        "| Claim | The paper says | Held | Why (not held) | Evidence (ours) "
        "| With 95 % CIs (ours) |"
    )
    assert lines[10].startswith("| world1/SIE-lowest-c | In Simulated World 1, ")
    first = ledger[0]
    assert lines[10].endswith(f"| {first['ci_verdict']}: {first['ci_evidence']} |")
    assert "| H4 | H4 is supported: " in text
    assert "could not be evaluated" not in text
    for heading in (
        "## Hypotheses",
        "### Table 3",
        "### Table 4",
        "### Table 5",
        "## Where our ordering differs from the paper",
        "## Robustness of the comparisons",
        "## Idiotypic difference rate",
        "## Long-term learning (GA)",
        "## Figures",
        "## Run configuration",
        "## Timings",
    ):
        assert heading in text, heading
    assert "| SIE | 6 |" in text  # n column of Table 3
    # Table 3 gives our means with their bootstrap intervals, labelled.
    assert "| System | n | c ours [95 % CI] / paper | τ (s) ours [95 % CI] / paper |" in text
    assert "95 % percentile bootstrap confidence interval of our mean (2000 resamples" in text
    t3, ci = tables["table3"]["world1"]["SIE"], tables["table3_ci"]["world1"]["SIE"]
    cell = f"| {t3['tau']:.0f} [{ci['tau'][0]:.0f}, {ci['tau'][1]:.0f}] / 562"
    assert cell in text
    assert "*With 95 % CIs* (holds): world1: SIE f [" in text  # under H1
    assert "trapped (s), ours |" in text and "| 12.5 |" in text
    assert "c + τ may exceed total" in text
    assert "| URL-R1 | 17 / 43 | 17 / 30 † | 17 / 57 |" in text  # 1 run of 6, by both caps
    assert "/ 562" in text  # the paper's value beside ours
    assert "**world1, Table 3 f**" in text  # HDC now beats SRL
    assert "SRL 3 vs 2" in text
    assert "| 0 | 300.0 | 297.0 |" in text  # LTL best f at generation 0 and final
    assert '"seed": 3' in text and "stl.world1_s" in text
    for world in protocol.WORLDS:
        assert (tmp_path / "figures" / f"box_{world}.png").stat().st_size > 0
    assert (tmp_path / "figures" / "traj_world1.png").exists()
    assert (tmp_path / "figures" / "traj_real.png").exists()
    assert not (tmp_path / "figures" / "traj_world2.png").exists()
    assert (tmp_path / "figures" / "ltl_fitness.png").exists()
    assert drawn.count("world1") == len(protocol.SYSTEMS)


def test_ltl_section_reads_the_evolve_summary_format():
    # The real evolve.py summary (the shipped seed's): its per-population keys must reach the table.
    summary = json.loads((ROOT / "checkpoints" / "default" / "summary.json").read_text())
    text = "\n".join(report._ltl_section(summary, None))
    for i, p in enumerate(summary["populations"]):
        row = (
            f"| {i} | {p['best_f_generation_0']:.1f} | {p['best_f_final_generation']:.1f} "
            f"| {p['best_f_overall']:.1f} |"
        )
        assert row in text, row
    assert "| 0 | – |" not in text


def test_write_report_minimal(tmp_path, paper):
    results = {"world2": {"SIE": [trial(100), trial(120)], "SRL": [trial(300), trial(340)]}}
    path = report.write_report(
        tmp_path, stats.build_tables(results), results, paper, None, {}, None
    )
    text = path.read_text()
    assert "No LTL summary was given." in text
    assert "No timings were given." in text
    assert "No trial reported an idiotypic difference rate." in text
    assert "**H4.** Supported." in text
    # Two systems in one world: most claims cannot be evaluated, and the report says so.
    ledger = claims.claims(results)
    counts = claims.summary(ledger)
    assert counts["evaluated"] < counts["total"] == 32
    assert text.splitlines()[2] == claims.headline(counts)
    assert f"{32 - counts['evaluated']} of the paper's 32 claims could not be evaluated" in text
    assert "| world1/SIE-lowest-c |" in text and "| – |  | No results for world1. |" in text
    assert "trapped (s)" in text  # the records carry trapped_s (0 here)


def test_write_report_uses_the_given_ledger(tmp_path, paper):
    results = {"world2": {"SIE": [trial(100), trial(120)], "SRL": [trial(300), trial(340)]}}
    ledger = [{"id": "X", "world": None, "text": "a claim", "held": False, "evidence": "a|b"}]
    path = report.write_report(
        tmp_path,
        stats.build_tables(results),
        results,
        paper,
        None,
        {},
        None,
        claims_ledger=ledger,
    )
    lines = path.read_text().splitlines()
    assert lines[2] == "**0 of 1 of the paper's claims reproduced**"
    # What does not reproduce (SRL faster than the paper's), then the claims. A pipe in the
    # evidence is escaped; no evidence given, a claim without a measured mechanism says so.
    assert lines[4].startswith("**What does not reproduce.** The paper's slow RL-only system")
    assert lines[8] == "| X | a claim | ✗ | not reproduced (no mechanism measured) | a\\|b |"
    assert sorted(p.name for p in (tmp_path / "figures").iterdir()) == ["box_world2.png"]


def test_write_report_without_intervals(tmp_path, paper):
    # Tables from before the intervals (no "table3_ci"): plain means, no brackets.
    results = {"world2": {"SIE": [trial(100), trial(120)], "SRL": [trial(300), trial(340)]}}
    tables = stats.build_tables(results)
    del tables["table3_ci"], tables["ci"]
    text = report.write_report(tmp_path, tables, results, paper, None, {}, None).read_text()
    assert "| System | n | c ours / paper |" in text and "bootstrap" not in text
    assert "| SIE | 2 | 0.0 / 2 | 110 / 659 " in text


def test_write_report_sets_contenders_beside_sie_and_hdc(tmp_path, paper):
    results = {"world2": {"SIE": [trial(100), trial(120)], "HDC": [trial(300), trial(340)]}}
    nn = {"world2": {"NN": [trial(200), trial(4000, 2)]}}  # f 100, 2008; one failed by time
    tables = stats.contender_tables(results, nn)
    tables["contenders"] = {"NN": {"spec": "mine.py:nn", "sha256": "ab" * 32, "about": "An MLP."}}
    text = report.write_report(
        tmp_path, stats.build_tables(results), results, paper, None, {}, None,
        contenders=tables, contender_results=nn,
    ).read_text()  # fmt: skip
    section = text[text.index("## Beyond the paper") :]
    t4 = tables["table4"]["world2"]
    levels = [t4[f"NN vs {other}"][m] for other in ("SIE", "HDC") for m in stats.METRICS]
    lo, hi = tables["table3_ci"]["world2"]["NN"]["f"]
    assert (lo, hi) == (100.0, 2008.0)  # two trials: the bootstrap's means lie between them
    ci5 = tables["table5_ci"]["world2"]["NN"]["total"]
    assert (
        f"| NN | 1.0 [0.0, 2.0] | 2100 [200, 4000] | 1054 [100, 2008] | 50.0 "
        f"[{ci5[0]:.1f}, {ci5[1]:.1f}] | " + " | ".join(map(str, levels)) + " |"
    ) in section
    assert "| SIE | 0.0 [0.0, 0.0] | 110 [100, 120] | 55 [50, 60] | 0.0 [0.0, " in section
    assert "- **NN**: An MLP. Given as `mine.py:nn` (sha256 abababababab)." in section
    assert "same protocol, seed, worlds and reset streams as SIE and HDC" in section
    # Without contenders there is no such section.
    plain = report.write_report(
        tmp_path, stats.build_tables(results), results, paper, None, {}, None
    ).read_text()
    assert "Beyond the paper" not in plain


def test_report_gives_the_calibration_point_lock_ups_and_uie_against_url(tmp_path, paper):
    results = synthetic_results(paper)
    for by in results.values():
        for label, records in by.items():
            locked = {"SIE": 3.0, "SRL": 40.0}.get(label, 0.0)
            replaced = 7 if label.startswith("URL") else 0
            by[label] = [r | {"locked_s": locked, "replaced": replaced} for r in records]
    tables = stats.build_tables(results)
    hold1 = {w: {"SIE": [trial(100, 0, 0.15)] * 2} for w in results}
    tables["calibration"] = stats.calibration(results, hold1, {"k1": 0.85, "k2": 1.1})
    text = report.write_report(tmp_path, tables, results, paper, None, {}, None).read_text()
    assert "### The calibration point" in text
    assert "| world1 | 20.0 % | 15.0 % | 20 % |" in text  # synthetic SIE rate 0.2; hold=1 0.15
    assert "### Lock-ups" in text and "5 × 0.05 = 0.25" in text
    # Locked of trapped (12.5 s in every synthetic trial) for SIE and SRL, in the text and table.
    assert "SRL world1 40 of 12 s" in text and "| world1 | 3 of 12 | 40 of 12 |" in text
    assert "SIE spends less time locked than SRL in 3 of 3 worlds (world1, world2, real)." in text
    assert "locked (s), ours |" in text
    assert "### Unseeded systems: UIE against URL" in text
    f = tables["table3"]["world1"]
    uie, url = f["UIE-R2"]["f"], f["URL-R2"]["f"]
    assert f"| world1 | R2 | {uie:.0f} / 0.0 / 12 | {url:.0f} / 7.0 / 12 |" in text
