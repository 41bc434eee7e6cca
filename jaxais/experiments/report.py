"""The results report: the claims ledger, our Tables 3-5 beside the paper's, H1-H4, robustness
tests and figures (matplotlib on the Agg canvas, no pyplot), in the protocol's order."""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from . import claims, explanations, protocol, stats
from .plotting import new_figure, save_figure
from .protocol import load_paper_tables

__all__ = ["load_paper_tables", "ordering_differences", "write_report"]

WorldDrawer = Callable[..., None]
"""``world_drawer(ax, world_name[, placement])`` draws a world (boxes and goal as placed)."""

_T3_COLS = (("c", "c", 1), ("tau", "τ (s)", 0), ("f", "f", 0))  # key, header, decimals
_T5_COLS = (("c", "c cap", 0), ("tau", "τ cap", 0), ("total", "total", 0))
_T3_TITLE = "Table 3: mean c, τ and f"
_T5_TITLE = "Table 5: failure rates (%) by collision cap, by time cap and overall"
_METRIC_NAME = {"c": "c", "tau": "τ", "f": "f", "total": "total"}
_LEVEL = f"{100 * stats.CI_LEVEL:g} %"
_RULE_WORDS = {"episode": "per contact episode", "reading": "per reading (Vm ≥ 2400)"}
_SIG_LEVEL = stats.significance_level(protocol.ALPHA)  # 99


def _worlds(*tables: Mapping[str, Any]) -> list[str]:
    return stats.in_order([w for t in tables for w in t], protocol.WORLDS)


def _rows(*rows: Mapping[str, Any]) -> list[str]:
    return stats.in_order([s for r in rows for s in r], protocol.SYSTEMS)


def _num(x: Any, decimals: int = 0) -> str:
    if x is None:
        return "–"
    x = float(x)
    if math.isinf(x):
        return "+inf" if x > 0 else "−inf"
    return f"{x:.{decimals}f}"


def _span(iv: Sequence[float] | None, decimals: int) -> str:
    return f" [{_num(iv[0], decimals)}, {_num(iv[1], decimals)}]" if iv else ""


def _p(p: float) -> str:
    return "0" if p == 0 else f"{p:.2g}"


def _table(header: Sequence[str], body: Sequence[Sequence[str]], align: str = "") -> list[str]:
    align = align or "l" + "r" * (len(header) - 1)
    sep = [{"r": "---:", "c": ":---:"}.get(a, "---") for a in align]
    lines = ["| " + " | ".join(header) + " |", "| " + " | ".join(sep) + " |"]
    lines += ["| " + " | ".join(row) + " |" for row in body]
    return lines + [""]


def _ranks(values: Mapping[str, float]) -> dict[str, int]:
    """Competition ranks (1 = lowest = best; ties share the lower rank)."""
    return {k: 1 + sum(w < v for w in values.values()) for k, v in values.items()}


def _order_string(values: Mapping[str, float]) -> str:
    items = sorted(values.items(), key=lambda kv: kv[1])
    out = items[0][0]
    for (_, prev), (name, v) in zip(items, items[1:], strict=False):
        out += (" = " if v == prev else " < ") + name
    return out


def ordering_differences(
    ours: Mapping[str, Mapping[str, Mapping[str, Any]]],
    paper: Mapping[str, Mapping[str, Mapping[str, Any]]],
    columns: Sequence[str],
) -> list[dict[str, Any]]:
    """Where the systems' ranks (lower is better) differ from the paper's, per world and column;
    ours rounded to integers first, the paper's precision, so rounding alone breaks no tie.

    Returns:
        ``[{"world", "column", "systems": [whose rank differs], "ours": {system: rank},
        "paper": {...}, "ours_order": str, "paper_order": str}]``.
    """
    out = []
    for world in _worlds(ours, paper):
        common = [s for s in _rows(ours.get(world, {})) if s in paper.get(world, {})]
        if len(common) < 2:
            continue
        for col in columns:
            mine = {s: float(round(ours[world][s][col])) for s in common}
            theirs = {s: float(paper[world][s][col]) for s in common}
            r_ours, r_paper = _ranks(mine), _ranks(theirs)
            differ = [s for s in common if r_ours[s] != r_paper[s]]
            if differ:
                out.append(
                    dict(world=world, column=col, systems=differ, ours=r_ours, paper=r_paper)
                    | {"ours_order": _order_string(mine), "paper_order": _order_string(theirs)}
                )
    return out


def _claims_section(
    ledger: Sequence[Mapping[str, Any]],
    rule_claims: Mapping[str, Sequence[Mapping[str, Any]]] | None = None,
    evidence: explanations.Evidence | None = None,
    opening: Sequence[str] = (),
) -> list[str]:
    """The ledger's headline, the ``opening`` lines, the other headlines, a note on unevaluated
    claims and a row per claim, with each claim under the other counting rules
    (``rule_claims``: rule -> ledger) and why a claim fails (:func:`explanations.why`)."""
    counts = claims.summary(ledger)
    lines = [claims.headline(counts), ""]
    rules = dict(rule_claims or {})
    for rule, other in rules.items():
        k = claims.summary(other)
        lines += [
            f"Counting c {_RULE_WORDS[rule]} instead: {k['reproduced']} of {k['evaluated']} "
            "(the column beside *Held*; the trials are the same).",
            "",
        ]
    with_ci = any("ci_verdict" in c for c in ledger)
    if with_ci:
        lines += [claims.ci_headline(claims.ci_summary(ledger)), ""]
    lines += opening
    missing = counts["total"] - counts["evaluated"]
    if missing:
        lines += [
            f"{missing} of the paper's {counts['total']} claims could not be evaluated (no "
            "results for their world or systems); they are marked – below.",
            "",
        ]
    mark = {True: "✓", False: "✗", None: "–"}
    header = ["Claim", "The paper says", "Held"]
    header += [f"Held, c {_RULE_WORDS[r]}" for r in rules] + ["Why (not held)", "Evidence (ours)"]
    held_by = {r: {c["id"]: c["held"] for c in other} for r, other in rules.items()}
    evidence = evidence or explanations.Evidence()
    body = [
        [c["id"], c["text"], mark[c["held"]]]
        + [mark[held_by[r].get(c["id"])] for r in rules]
        + [explanations.why(c, evidence), c["evidence"]]
        for c in ledger
    ]
    if with_ci:
        header.append(f"With {_LEVEL} CIs (ours)")
        for row, c in zip(body, ledger, strict=True):
            verdict = c.get("ci_verdict")
            row.append("–" if verdict is None else f"{verdict}: {c.get('ci_evidence', '')}")
    body = [[cell.replace("|", "\\|") for cell in row] for row in body]
    return lines + _table(header, body, "llc" + "c" * len(rules) + "ll" + "l" * with_ci)


def _side_by_side(
    title: str,
    ours: Mapping[str, Any],
    paper: Mapping[str, Any],
    cols: Sequence[tuple[str, str, int]],
    diffs: Sequence[Mapping[str, Any]],
    n_trials: Mapping[str, Mapping[str, int]] | None,
    extra: Sequence[tuple[str, Mapping[str, Mapping[str, Any]]]] = (),
    intervals: Mapping[str, Mapping[str, Mapping[str, Sequence[float]]]] | None = None,
    note: str = "",
) -> list[str]:
    """Our table beside the paper's, per world, cells ranked unlike the paper's (``diffs``,
    :func:`ordering_differences`) marked; ``extra``: ``(header, {world: {system: v}})`` columns
    of ours alone; ``intervals`` (:data:`stats.CIs`): ``[lo, hi]`` after our values."""
    flagged = {(d["world"], s, d["column"]) for d in diffs for s in d["systems"]}
    lines = [f"### {title}", ""] + ([note, ""] if note else [])
    ci = f" [{_LEVEL} CI]" if intervals else ""
    header = ["System"] + (["n"] if n_trials is not None else [])
    header += [f"{h} ours{ci} / paper" for _, h, _ in cols] + [head for head, _ in extra]
    for world in _worlds(ours, paper):
        mine, theirs = ours.get(world, {}), paper.get(world, {})
        body = []
        for s in _rows(mine, theirs):
            row = [s] + ([str(n_trials.get(world, {}).get(s, "–"))] if n_trials is not None else [])
            for key, _, dec in cols:
                a, b = mine.get(s, {}).get(key), theirs.get(s, {}).get(key)
                mark = " †" if (world, s, key) in flagged else ""
                span = _span((intervals or {}).get(world, {}).get(s, {}).get(key), dec)
                row.append(f"{_num(a, dec)}{span} / {_num(b)}{mark}")
            row += [_num(values.get(world, {}).get(s), 1) for _, values in extra]
            body.append(row)
        lines += [f"**{world}**", ""] + _table(header, body)
    return lines


_FASTER = 1.5
"""Ours "faster" than the paper's: τ below the paper's by this factor."""
_TRAPPED = 0.5
"""Unseeded robots "circle": trapped for more than this share of every run, on average."""


def _honest_paragraph(tables: Mapping[str, Any], paper: Mapping[str, Any]) -> list[str]:
    """What does not reproduce, plainly, from our tables beside the paper's: each sentence only
    where its worlds and systems have results and our numbers show it."""
    t3, t5 = tables["table3"], tables["table5"]
    p3, p5 = paper.get("table3", {}), paper.get("table5", {})
    hyp, out = tables.get("hypotheses", {}), []
    real = protocol.REAL_WORLD
    seeded = [s for s in protocol.SEEDED if s in t3.get(real, {}) and s in p3.get(real, {})]
    ratios = [p3[real][s]["tau"] / max(t3[real][s]["tau"], 1e-9) for s in seeded]
    if ratios and min(ratios) > _FASTER:
        out.append(
            "In the real pen, whose size the paper gives and ours matches, our seeded robots "
            f"reach the target {min(ratios):.0f}-{max(ratios):.0f}x faster than the paper's (τ "
            + ", ".join(f"{s} {t3[real][s]['tau']:.0f} s vs {p3[real][s]['tau']:.0f}"
                        for s in seeded)
            + ")."
        )  # fmt: skip
    fast = [
        w
        for w in protocol.WORLDS
        if "SRL" in t3.get(w, {}) and "SRL" in p3.get(w, {})
        and t3[w]["SRL"]["tau"] * _FASTER < p3[w]["SRL"]["tau"]
    ]  # fmt: skip
    if fast:
        out.append(
            "The paper's slow RL-only system is not reproduced: our SRL's τ is "
            + ", ".join(f"{t3[w]['SRL']['tau']:.0f} s in {w} (paper {p3[w]['SRL']['tau']:.0f})"
                        for w in fast)
            + "."
        )  # fmt: skip
    sim = [w for w in protocol.WORLDS[:2] if w in t5 and w in p5]
    unseeded = [(w, s) for w in sim for s in protocol.UNSEEDED if s in t5[w] and s in p5[w]]
    ours_c = max((t5[w][s]["c"] for w, s in unseeded), default=None)
    theirs = [p5[w][s]["c"] for w, s in unseeded]
    trapped = [
        (tables.get("trapped_s", {}).get(w, {}).get(s) or 0.0) / max(t3[w][s]["tau"], 1e-9)
        for w, s in unseeded
    ]
    if unseeded and ours_c < min(theirs) and min(trapped) > _TRAPPED:
        share = f", trapped {100 * min(trapped):.0f}-{100 * max(trapped):.0f} % of the run"
        out.append(
            "The unseeded failure mode is not reproduced: the paper's unseeded robots crash "
            f"(failures by the collision cap {min(theirs):.0f}-{max(theirs):.0f} % in the "
            f"simulated worlds), ours circle in open space{share}, and time out (failures by the "
            f"collision cap at most {ours_c:.0f} %)."
        )
    for h in ("H2", "H3"):
        tested = not hyp.get(h, {}).get("summary", "").startswith("Not testable")
        if h in hyp and tested and not hyp[h].get("supported"):
            out.append(f"{h} is not supported ({_H_WORDS[h]}).")
    w2 = t3.get("world2", {})
    if "SIE" in w2 and "HDC" in w2 and w2["HDC"]["f"] < w2["SIE"]["f"]:
        out.append(
            f"In world2 the hand-designed HDC beats SIE (f {w2['HDC']['f']:.0f} vs "
            f"{w2['SIE']['f']:.0f}): H3 reverses there."
        )
    if not out:
        return []
    return ["**What does not reproduce.** " + " ".join(out), ""]


_H_WORDS = {
    "H2": "the idiotypic network does not beat RL alone",
    "H3": "the idiotypic network does not beat the hand-designed controller in every world",
}


def _rule_extra(tables: Mapping[str, Any], table: str, cols: Sequence[tuple[str, str]]) -> list:
    """Extra columns of ``table`` under each other counting rule (``tables["by_rule"]``)."""
    out = []
    for rule, by in tables.get("by_rule", {}).items():
        for key, head in cols:
            values = {w: {s: row[key] for s, row in t.items()} for w, t in by[table].items()}
            out.append((f"{head} {_RULE_WORDS[rule]}, ours", values))
    return out


def _interval_note(settings: Mapping[str, Any]) -> str:
    """What Table 3's brackets are (``tables["ci"]``)."""
    level = 100 * float(settings.get("level", stats.CI_LEVEL))
    resamples = settings.get("resamples", stats.BOOTSTRAP_RESAMPLES)
    seed = settings.get("seed", stats.BOOTSTRAP_SEED)
    return (
        f"Brackets: {level:g} % percentile bootstrap confidence interval of our mean "
        f"({resamples} resamples of each system's trials with replacement, seed {seed}; c, τ "
        "and f from the same resamples)."
    )


def _table4_section(ours: Mapping[str, Any], paper: Mapping[str, Any]) -> list[str]:
    lines = [
        "### Table 4: significance levels 100 (1 − p), two-tailed Student's t (ours / paper)",
        "",
        f"Significant at the paper's 99 % level when the level is ≥ {_SIG_LEVEL}. "
        "‡ marks a cell where our verdict (significant or not) differs from the "
        "paper's. Levels carry no sign: see the mean differences in the robustness table.",
        "",
    ]
    header = ["Comparison"] + [f"{_METRIC_NAME[m]} ours / paper" for m in stats.METRICS]
    pairs = [f"{a} vs {b}" for a, b in protocol.COMPARISONS]
    for world in _worlds(ours, paper):
        mine, theirs = ours.get(world, {}), paper.get(world, {})
        body = []
        for pair in (p for p in pairs if p in mine or p in theirs):
            row = [pair]
            for m in stats.METRICS:
                a, b = mine.get(pair, {}).get(m), theirs.get(pair, {}).get(m)
                row.append(f"{_num(a)} / {_num(b)}" + (" ‡" if _differs(a, b) else ""))
            body.append(row)
        lines += [f"**{world}**", ""] + _table(header, body)
    return lines


def _differs(ours: float | None, paper: float | None) -> bool:
    """Whether two Table 4 levels give different verdicts at the paper's 99 %."""
    if ours is None or paper is None:
        return False
    return (ours >= _SIG_LEVEL) != (paper >= _SIG_LEVEL)


def _ordering_section(diffs3: list, diffs5: list, ours4: Mapping, paper4: Mapping) -> list[str]:
    lines = [
        "## Where our ordering differs from the paper",
        "",
        "Systems ranked from best (lowest) to worst per world and column; our values rounded to "
        "integers first, like the paper's. Cells marked † in Tables 3 and 5.",
        "",
    ]
    for label, diffs in (("Table 3", diffs3), ("Table 5", diffs5)):
        for d in diffs:
            col = _METRIC_NAME[d["column"]]
            moved = ", ".join(f"{s} {d['ours'][s]} vs {d['paper'][s]}" for s in d["systems"])
            lines += [
                f"- **{d['world']}, {label} {col}** (rank ours vs paper: {moved})",
                f"  - ours: {d['ours_order']}",
                f"  - paper: {d['paper_order']}",
            ]
    sig = [
        f"- {world}, Table 4 {pair}, {_METRIC_NAME[m]}: level {row[m]} (paper {ref[m]})"
        for world in _worlds(ours4, paper4)
        for pair, row in ours4.get(world, {}).items()
        if (ref := paper4.get(world, {}).get(pair)) is not None
        for m in stats.METRICS
        if _differs(row[m], ref[m])
    ]
    if sig:
        lines += ["", "Table 4 verdicts at 99 % that differ from the paper's (‡):", ""] + sig
    if not (diffs3 or diffs5 or sig):
        lines.append("No differences: every ranking and every 99 % verdict matches the paper.")
    return lines + [""]


def _hypotheses_section(
    ours: Mapping[str, Any], paper: Mapping[str, Any], rules: Mapping[str, Any] | None = None
) -> list[str]:
    """H1-H4 beside the paper's, and under each other counting rule (``rules``: rule ->
    :func:`stats.hypotheses`)."""

    def verdict(h: Mapping[str, Any] | None) -> str:
        return "–" if h is None else "supported" if h.get("supported") else "not supported"

    rules = rules or {}
    names = list(dict.fromkeys([*ours, *paper]))
    body = [
        [h, paper.get(h, {}).get("statement", ""), verdict(ours.get(h))]
        + [verdict(by.get(h)) for by in rules.values()]
        + [verdict(paper.get(h))]
        for h in names
    ]
    lines = ["## Hypotheses", ""]
    header = ["", "Hypothesis", "Ours", *(f"Ours, c {_RULE_WORDS[r]}" for r in rules), "Paper"]
    lines += _table(header, body, align="l" * len(header))
    for h in names:
        lines += [f"**{h}.** {ours.get(h, {}).get('evidence', 'Not evaluated.')}", ""]
        if "ci_summary" in ours.get(h, {}):
            held = "holds" if ours[h].get("ci_supported") else "does not hold"
            lines += [f"*With {_LEVEL} CIs* ({held}): {ours[h]['ci_summary']}", ""]
        if "paper_says" in paper.get(h, {}):
            lines += [f"*Paper:* {paper[h]['paper_says']}.", ""]
    return lines


def _robustness_section(comps: Mapping[str, Any], paper4: Mapping[str, Any]) -> list[str]:
    alpha = protocol.ALPHA
    lines = [
        "## Robustness of the comparisons",
        "",
        "τ is capped at 4000 s and c at 100, so their distributions are skewed and piled up at the "
        "caps; Student's t (the paper's test) assumes normal data with equal variances. Welch's t "
        "drops the equal-variance assumption and the Mann–Whitney U test is rank-based, so it is "
        "the one to trust for τ. Δ = mean A − mean B (negative: A better); U counts pairs with "
        f"A > B. The last column says whether all three tests agree at p < {alpha:g}.",
        "",
    ]
    header = ["Comparison", "", "Δ mean", "Student t (p)", "level ours / paper", "Welch t (p)"]
    header += ["Mann–Whitney U (p)", "Cohen's d", "tests agree"]
    for world in _worlds(comps):
        body = []
        for pair, by_metric in comps[world].items():
            for m, r in by_metric.items():
                ref = paper4.get(world, {}).get(pair, {}).get(m)
                sig = {r["student_p"] < alpha, r["welch_p"] < alpha, r["mwu_p"] < alpha}
                test = lambda stat, p, dec, r=r: f"{_num(r[stat], dec)} ({_p(r[p])})"
                body.append(
                    [pair, _METRIC_NAME[m], _num(r["mean_diff"], 1)]
                    + [test("student_t", "student_p", 2), f"{r['level']} / {_num(ref)}"]
                    + [test("welch_t", "welch_p", 2), test("mwu_u", "mwu_p", 1)]
                    + [_num(r["cohens_d"], 2), "yes" if len(sig) == 1 else "**no**"]
                )
        lines += [f"**{world}**", ""] + _table(header, body, align="llrrrrrrl")
    return lines


def _idiotypic_section(rates: Mapping[str, Any], paper: Mapping[str, Any]) -> list[str]:
    target = paper.get("protocol", {}).get("idiotypic_difference_rate_target_percent", 20)
    lines = [
        "## Idiotypic difference rate",
        "",
        "Mean over trials of the rate at which the idiotypic network's choice differs from the "
        f"best-matching antibody (as recorded by the engine). The paper tuned its constants for "
        f"about {target} %. Systems without a rate are left out.",
        "",
    ]
    worlds = _worlds(rates)
    systems = [
        s
        for s in _rows(*(rates[w] for w in worlds))
        if any(rates[w].get(s) is not None for w in worlds)
    ]
    if not systems:
        return lines[:2] + ["No trial reported an idiotypic difference rate.", ""]
    body = [[s] + [_num(rates[w].get(s), 3) for w in worlds] for s in systems]
    return lines + _table(["System", *worlds], body)


def _percent(rate: float | None) -> str:
    return "–" if rate is None else f"{100 * rate:.1f} %"


def _calibration_section(cal: Mapping[str, Any] | None) -> list[str]:
    """:func:`stats.calibration`'s difference rates beside the paper's."""
    if not cal:
        return []
    lines = [
        "### The calibration point",
        "",
        f'Section 5 chose k1 = {cal["k1"]:g} and k2 = {cal["k2"]:g} "to yield a mean '
        f'idiotypic difference rate of approximately {cal["paper_percent"]} %". '
        f"{cal['system']}'s rate at those constants, under our 1 s bouts (the default) and "
        "with a selection every 32 ms iteration (`hold=1`); alpha acts on the other "
        "antibodies only (section 4.3). "
        "`scripts/sweep.py --grid k1=... --grid k2=...` maps where the paper's rate lies.",
        "",
    ]
    body = [
        [w, _percent(r.get("default")), _percent(r.get("hold=1")), f"{cal['paper_percent']} %"]
        for w, r in cal["worlds"].items()
    ]
    return lines + _table(["World", "ours (1 s bouts)", "ours (hold=1)", "paper"], body)


def _lockup_section(tables: Mapping[str, Any]) -> list[str]:
    """Locked against trapped time for the seeded systems, and the lone-survivor mechanism."""
    locked, trapped = tables.get("locked_s") or {}, tables.get("trapped_s") or {}
    worlds = [w for w in locked if locked[w].get("SIE") is not None]
    if not worlds or not all(locked[w].get("SRL") is not None for w in worlds):
        return []

    def cell(w: str, s: str) -> str:
        return f"{_num(locked[w].get(s), 0)} of {_num(trapped.get(w, {}).get(s), 0)}"

    srl = "; ".join(f"{w} {cell(w, 'SRL')} s" for w in worlds)
    sie = "; ".join(f"{w} {cell(w, 'SIE')} s" for w in worlds)
    less = [w for w in worlds if locked[w]["SIE"] < locked[w]["SRL"]]
    body = [[w, cell(w, "SIE"), cell(w, "SRL")] for w in worlds]
    return [
        "### Lock-ups",
        "",
        "A robot is *locked* while it is trapped (within 0.1 m of one point for at least 10 s) "
        "and every selection in that stay repeats the antibody last selected for its antigen. "
        "One way in: when a collision column holds one antibody with a non-zero paratope, "
        "eq (4) with the σ0 floor returns that lone survivor to 5 × 0.05 = 0.25 after every "
        "negative score, so stage-1 selection picks it again and again while the robot pivots "
        "against a wall; only idiotypic selection (stage 3) can pass it over. Measured here, "
        f"mean locked of trapped time per run: SRL {srl}; SIE {sie}. SIE spends less time "
        f"locked than SRL in {len(less)} of {len(worlds)} worlds"
        + (f" ({', '.join(less)})." if less else ".")
        + " Whether SRL locks up at all depends on the LTL seed's sets: the seed ledger "
        "(`scripts/seeds.py`) gives both systems' lock-up time on each seed.",
        "",
        *_table(["World", "SIE locked of trapped (s)", "SRL locked of trapped (s)"], body),
    ]


def _unseeded_section(
    results_by_world: stats.ResultsByWorld, tables: Mapping[str, Any]
) -> list[str]:
    """UIE against URL: antibody replacements and trapped time (the penalty mechanism)."""
    pairs = [
        (w, r)
        for w, by in results_by_world.items()
        for r in ("R1", "R2")
        if f"UIE-{r}" in by and f"URL-{r}" in by
    ]
    if not pairs:
        return []
    replaced = stats.record_means(results_by_world, "replaced")
    body = []
    for w, r in pairs:
        row = [w, r]
        for label in (f"UIE-{r}", f"URL-{r}"):
            f = tables["table3"][w][label]["f"]
            trapped = tables["trapped_s"][w][label]
            row.append(f"{_num(f)} / {_num(replaced[w][label], 1)} / {_num(trapped)}")
        body.append(row)
    return [
        "### Unseeded systems: UIE against URL",
        "",
        "The paper's penalties remove 0.5 from an idiotypic robot's acting antibody and 1.0 "
        "from an RL-only robot's, and an unseeded robot replaces an antibody once its P falls "
        'below 0.1. A saturated antibody (P = 1, e.g. for "target unseen", antigen 0) of '
        "an unseeded idiotypic robot penalised by 0.5 stays above 0.1 and is never replaced, "
        "so UIE can keep a behaviour it circles with where URL replaces it. `scripts/ablate.py`"
        "'s variant `penalties=swapped` shows what swapping the two penalties does; the "
        "penalties stay the paper's rule. Each cell: mean f / antibodies replaced per run / "
        "trapped time (s).",
        "",
        *_table(["World", "Set", "UIE", "URL"], body),
    ]


def _source(source: Mapping[str, Any]) -> str:
    """How a contender was given, for its line in the report."""
    if source.get("spec"):
        sha = f" (sha256 {source['sha256'][:12]})" if source.get("sha256") else ""
        return f"`{source['spec']}`{sha}"
    if source.get("weights"):
        return f"weights {source['weights']}"
    return "an object given from Python (not regenerable from the command line)"


def _contenders_section(tables: Mapping[str, Any] | None) -> list[str]:
    """Contenders beyond the paper beside some of its systems (:func:`stats.contender_tables`)."""
    if not tables:
        return []
    names = list(tables["against"])
    against = " and ".join([", ".join(names[:-1]), names[-1]] if len(names) > 1 else names)
    lines = [
        "## Beyond the paper",
        "",
        f"Controllers beyond the paper's, each run in a pool of its own under the same protocol, "
        f"seed, worlds and reset streams as {against} (their records do not depend on it). "
        f"Brackets: {_LEVEL} intervals (bootstrap for the means, Wilson for the failure rate); "
        f"the last columns are Table 4's significance levels 100 (1 − p), two-tailed Student's "
        f"t, against {against} (significant at the paper's 99 % level when ≥ {_SIG_LEVEL}).",
        "",
    ]
    for label, source in tables.get("contenders", {}).items():
        about = f": {source['about']}" if source.get("about") else ""
        lines.append(f"- **{label}**{about} Given as {_source(source)}.")
    lines.append("")
    t3, ci3 = tables["table3"], tables["table3_ci"]
    t5, ci5 = tables["table5"], tables["table5_ci"]
    levels = tables["table4"]
    header = ["System", *(head for _, head, _ in _T3_COLS), "failed (%)"]
    header += [f"vs {o}: {_METRIC_NAME[m]}" for o in names for m in stats.METRICS]
    for world in t3:
        body = []
        for s, row in t3[world].items():
            cells = [s] + [
                _num(row[key], dec) + _span(ci3[world][s][key], dec) for key, _, dec in _T3_COLS
            ]
            cells.append(_num(t5[world][s]["total"], 1) + _span(ci5[world][s]["total"], 1))
            for other in names:
                level = levels.get(world, {}).get(f"{s} vs {other}")
                cells += [_num(level[m]) if level else "–" for m in stats.METRICS]
            body.append(cells)
        lines += [f"**{world}**", ""] + _table(header, body)
    return lines


def _ltl_section(ltl: Mapping[str, Any] | None, figure: str | None) -> list[str]:
    lines = ["## Long-term learning (GA)", ""]
    if ltl is None:
        return lines + ["No LTL summary was given.", ""]
    pops = ltl.get("populations", [])
    if pops:
        keys = ["best_f_generation_0", "best_f_final_generation"]
        head = ["Population", "best f, generation 0", "best f, final generation"]
        if any(p.get("best_f_overall") is not None for p in pops):
            keys.append("best_f_overall")
            head.append("best f, any generation (the seed)")
        lines += _table(
            head, [[str(i)] + [_num(p.get(k), 1) for k in keys] for i, p in enumerate(pops)]
        )
    extra = {k: v for k, v in ltl.items() if k not in ("populations", "generations") and _scalar(v)}
    if extra:
        lines += _table(["Quantity", "Value"], [[k, _value(v)] for k, v in extra.items()], "lr")
    if figure:
        lines += [f"![GA fitness per generation]({figure})", ""]
    return lines


def _scalar(v: Any) -> bool:
    return v is None or isinstance(v, str | bool | int | float | np.generic)


def _value(v: Any) -> str:
    if isinstance(v, float | np.floating) and not isinstance(v, bool):
        return f"{float(v):.4g}"
    return str(v)


def _flatten(d: Mapping[str, Any], prefix: str = "") -> list[tuple[str, Any]]:
    out: list[tuple[str, Any]] = []
    for k, v in d.items():
        key = f"{prefix}{k}"
        out += _flatten(v, key + ".") if isinstance(v, Mapping) else [(key, v)]
    return out


def _config_section(config: Mapping[str, Any], timings: Mapping[str, Any] | None) -> list[str]:
    text = json.dumps(stats.jsonable(config), indent=2, default=str)
    lines = ["## Run configuration", "", "```json", text, "```", "", "## Timings", ""]
    if not timings:
        return lines + ["No timings were given.", ""]
    return lines + _table(["Stage", "Value"], [[k, _value(v)] for k, v in _flatten(timings)], "lr")


def _box_figure(
    world: str,
    results: Mapping[str, Sequence[Mapping[str, Any]]],
    paper3: Mapping[str, Any],
    caps: Mapping[str, float],
    path: Path,
) -> None:
    systems = _rows({s: t for s, t in results.items() if len(t) > 0})
    fig = new_figure((4.2 * len(stats.METRICS), 4.0))
    for ax, m in zip(fig.subplots(1, len(stats.METRICS)), stats.METRICS, strict=True):
        data = [stats.metric_values(results[s], m) for s in systems]
        x = np.arange(1, len(systems) + 1)
        ax.boxplot(data, positions=x, widths=0.6, showfliers=True)
        ax.plot(x, [d.mean() for d in data], "^", color="tab:blue", label="our mean")
        px = [(i, paper3[s][m]) for i, s in zip(x, systems, strict=True) if s in paper3]
        if px:
            ax.plot(*zip(*px, strict=True), "x", color="tab:red", ms=8, label="paper mean")
        if m in caps:
            ax.axhline(caps[m], color="0.5", ls="--", lw=0.8, label="cap")
        ax.set_xticks(x, systems, rotation=45)
        ax.set_title(f"{world}: {_METRIC_NAME[m]}")
        ax.grid(axis="y", alpha=0.3)
    ax.legend(loc="best", fontsize="small")
    save_figure(fig, path, dpi=110)


def _trajectory_figure(
    world: str,
    trajectories: Mapping[str, np.ndarray],
    drawer: WorldDrawer | None,
    path: Path,
    placements: Mapping[str, Any] | None = None,
) -> None:
    systems = _rows(trajectories)
    cols = min(4, len(systems))
    rows = math.ceil(len(systems) / cols)
    fig = new_figure((3.6 * cols, 3.6 * rows))
    axes = fig.subplots(rows, cols, squeeze=False).ravel()
    for ax, s in zip(axes, systems, strict=False):
        if drawer is not None:
            # The boxes and goal where this trial had them (random per trial in some worlds).
            placement = (placements or {}).get(s)
            drawer(ax, world, *([] if placement is None else [placement]))
        xy = np.asarray(trajectories[s], dtype=float).reshape(-1, 2)
        ax.plot(xy[:, 0], xy[:, 1], lw=1.0, color="tab:blue")
        if len(xy):
            ax.plot(*xy[0], "o", color="tab:green", ms=6, label="start")
            ax.plot(*xy[-1], "*", color="tab:red", ms=10, label="end")
        ax.set_aspect("equal")
        ax.set_title(s)
    for ax in axes[len(systems) :]:
        ax.set_axis_off()
    axes[0].legend(loc="best", fontsize="small")
    fig.suptitle(f"{world}: one example trajectory per system")
    save_figure(fig, path, dpi=110)


def _ltl_figure(ltl: Mapping[str, Any], out: Path) -> str | None:
    """Draw ``out/figures/ltl_fitness.png`` and return its name (None: no generations)."""
    gens = sorted(ltl.get("generations", []), key=lambda g: g["generation"])
    if not gens:
        return None
    fig = new_figure((7.0, 4.5))
    ax = fig.subplots()
    g = [row["generation"] for row in gens]
    for i in range(len(gens[0]["populations"])):
        color = f"C{i % 10}"
        best = [row["populations"][i].get("best_f", np.nan) for row in gens]
        mean = [row["populations"][i].get("mean_f", np.nan) for row in gens]
        ax.plot(g, best, "-", color=color, label=f"population {i}")
        ax.plot(g, mean, "--", color=color, alpha=0.6)
    ax.set_xlabel("generation")
    ax.set_ylabel("f (lower is better)")
    ax.set_title("LTL: best (solid) and mean (dashed) f per population")
    ax.grid(alpha=0.3)
    ax.legend(fontsize="small")
    name = "figures/ltl_fitness.png"
    save_figure(fig, out / name, dpi=110)
    return name


def write_report(
    out_dir: str | Path,
    tables: Mapping[str, Any],
    results_by_world: stats.ResultsByWorld,
    paper: Mapping[str, Any],
    ltl_summary: Mapping[str, Any] | None,
    config: Mapping[str, Any],
    timings: Mapping[str, Any] | None,
    example_trajectories: Mapping[str, Mapping[str, np.ndarray]] | None = None,
    world_drawer: WorldDrawer | None = None,
    claims_ledger: Sequence[Mapping[str, Any]] | None = None,
    example_placements: Mapping[str, Mapping[str, Any]] | None = None,
    contenders: Mapping[str, Any] | None = None,
    contender_results: stats.ResultsByWorld | None = None,
    rule_claims: Mapping[str, Sequence[Mapping[str, Any]]] | None = None,
    evidence: explanations.Evidence | None = None,
) -> Path:
    """Write ``out_dir/report.md`` (claims ledger, H1-H4, tables beside the paper's, robustness,
    difference rates, contenders, LTL, figures, configuration) and ``out_dir/figures/``.

    Args:
        tables: :func:`stats.build_tables` of ``results_by_world`` (``{world: {system:
            [record]}}``), with ``"calibration"`` optionally.
        paper: :func:`load_paper_tables`.
        ltl_summary: an ``evolve.py`` ``summary.json`` (``populations`` tabulated, ``generations``
            drawn, scalars listed as they are) or None.
        config, timings: the run configuration (shown as JSON) and ``{stage: seconds or dict}``.
        example_trajectories: ``{world: {system: xy [T, 2]}}``, drawn over ``world_drawer``'s
            world with ``example_placements`` (``{world: {system: placement}}``).
        claims_ledger: :func:`claims.claims` of ``results_by_world`` (computed when None).
        contenders: :func:`stats.contender_tables` with ``"contenders"`` (label -> source), a
            section of its own; ``contender_results`` (``{world: {label: [record]}}``) join the
            box figures.
        rule_claims: the claims under each other counting rule (rule -> ledger,
            :func:`claims.by_rule`), beside ours; ``tables["by_rule"]`` (:func:`stats.rule_tables`)
            adds those rules' Tables 3 and 5 columns and H1-H4.
        evidence: what the claims' "why" column reads (:func:`explanations.load`).

    Returns:
        The path of ``report.md``.
    """
    out = Path(out_dir)
    (out / "figures").mkdir(parents=True, exist_ok=True)
    default_caps = {"c": protocol.COLLISION_CAP, "tau": protocol.TAU_CAP}
    caps = paper.get("protocol", {}).get("caps", default_caps)

    p3, p4, p5 = (paper.get(k, {}) for k in ("table3", "table4", "table5"))
    figures: list[tuple[str, str]] = []
    for world in _worlds(results_by_world):
        name = f"figures/box_{world}.png"
        drawn = results_by_world[world] | (contender_results or {}).get(world, {})
        _box_figure(world, drawn, p3.get(world, {}), caps, out / name)
        figures.append((f"{world}: c, τ and f per system", name))
    for world, trajectories in (example_trajectories or {}).items():
        if trajectories:
            name = f"figures/traj_{world}.png"
            placements = (example_placements or {}).get(world)
            _trajectory_figure(world, trajectories, world_drawer, out / name, placements)
            figures.append((f"{world}: example trajectories", name))
    ltl_fig = _ltl_figure(ltl_summary, out) if ltl_summary else None

    n_trials = {w: {s: len(t) for s, t in r.items()} for w, r in results_by_world.items()}
    diffs3 = ordering_differences(tables["table3"], p3, stats.METRICS)
    diffs5 = ordering_differences(tables["table5"], p5, stats.FAILURE_COLUMNS)

    extra = [
        (head, tables[key])
        for head, key in (("trapped (s), ours", "trapped_s"), ("locked (s), ours", "locked_s"))
        if any(v is not None for row in tables.get(key, {}).values() for v in row.values())
    ]

    lines = ["# jaxais results beside Whitbrook, Aickelin & Garibaldi (2008)", ""]
    lines += _claims_section(
        claims.claims(results_by_world) if claims_ledger is None else claims_ledger,
        rule_claims,
        evidence,
        _honest_paragraph(tables, paper),
    )
    lines += [
        f"Paper: {paper.get('source', 'see jaxais/data/paper_tables.json')}",
        "",
        "Lower is better for c (collisions), τ (seconds) and f = (8c + τ)/2; the means use c "
        "capped at 100, as the paper's Table 3 does. Each cell reads *ours / paper*; – marks a "
        "value that does not exist. † marks a system whose rank among the systems of that world "
        "and column differs from the paper's."
        + (
            " *Trapped* is the mean simulated time (s) a robot spent within 0.1 m of one point "
            "for at least 10 s, *locked* the part of it in which the same antibody kept being "
            "selected for each antigen (ours; the paper has no such columns)."
            if extra
            else ""
        ),
        "",
    ]
    by_rule = {r: t["hypotheses"] for r, t in tables.get("by_rule", {}).items()}
    lines += _hypotheses_section(tables["hypotheses"], paper.get("hypotheses", {}), by_rule)
    lines += ["## Tables", ""]
    intervals = tables.get("table3_ci")
    note = _interval_note(tables.get("ci", {})) if intervals else ""
    t3, t5 = tables["table3"], tables["table5"]
    extra += _rule_extra(tables, "table3", (("c", "c"), ("f", "f")))
    extra5 = _rule_extra(tables, "table5", (("c", "failed by c (%)"), ("total", "failed (%)")))
    lines += _side_by_side(_T3_TITLE, t3, p3, _T3_COLS, diffs3, n_trials, extra, intervals, note)
    lines += _side_by_side(_T5_TITLE, t5, p5, _T5_COLS, diffs5, None, extra5)
    lines += [
        "A run can breach both caps (more than 100 collisions and no finish by 4000 s), so the "
        "c-cap and τ-cap columns overlap and c + τ may exceed total, in ours as in the paper's.",
        "",
    ]
    lines += _table4_section(tables["table4"], p4)
    lines += _ordering_section(diffs3, diffs5, tables["table4"], p4)
    lines += _robustness_section(stats.comparisons(results_by_world), p4)
    lines += _idiotypic_section(tables.get("idiotypic_difference_rate", {}), paper)
    lines += _calibration_section(tables.get("calibration"))
    lines += _lockup_section(tables)
    lines += _unseeded_section(results_by_world, tables)
    lines += _contenders_section(contenders)
    lines += _ltl_section(ltl_summary, ltl_fig)
    lines += ["## Figures", ""]
    for caption, name in figures:
        lines += [f"**{caption}**", "", f"![{caption}]({name})", ""]
    lines += _config_section(config, timings)

    path = out / "report.md"
    path.write_text("\n".join(lines).rstrip() + "\n", encoding="utf-8")
    return path
