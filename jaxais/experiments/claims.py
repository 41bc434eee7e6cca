"""The paper's 32 qualitative claims, each checked against our results (the claims ledger).

Per world [paper, section 6]: SIE has the lowest mean c, tau and f (ties allowed: the paper calls
SIE's c lowest in World 2, where HDC ties it), a 0 % failure rate, f significantly below each
unseeded system's (Student's t, p < alpha), and SRL and UIE-R1 each a lower mean f than URL-R1:
10 + 10 + 8 claims, plus H1-H4 (:func:`stats.hypotheses`). A claim without results is not
evaluated (``held`` None). Each is also read with 95 % intervals [ours]: ``ci_held`` needs
``held`` and every comparison's intervals separated as claimed (:func:`stats.ci_below`; a 0 %
rate: its Wilson interval contains 0); ``ci_verdict`` is one of :data:`CI_VERDICTS`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from . import protocol, stats

__all__ = [
    "CI_VERDICTS",
    "HELD_OVERLAP",
    "HELD_SEPARATED",
    "HELD_ZERO_IN_CI",
    "HYPOTHESES",
    "by_rule",
    "NOT_HELD_BY_TEST",
    "NOT_HELD_OVERLAP",
    "NOT_HELD_SEPARATED",
    "NOT_HELD_ZERO_OUT",
    "ci_headline",
    "ci_summary",
    "claims",
    "document",
    "headline",
    "summary",
]

HYPOTHESES = {
    "H1": "Seeded STL systems outperform unseeded STL systems.",
    "H2": "Seeded STL systems that employ idiotypic effects outperform seeded systems that do not.",
    "H3": "Seeded STL systems that employ idiotypic effects outperform fixed, hand-designed "
    "strategies.",
    "H4": "As long as the LTL-derived behaviours are sufficiently diverse, antibody replacement "
    "should not be necessary in the STL phase.",
}
"""The paper's hypotheses (section 2), verbatim."""

CI_VERDICTS = (
    "held, CIs separated",
    "held, CIs overlap",
    "not held, CIs overlap",
    "not held, CIs separated",
    "not held, CIs separated as claimed",  # failed only its t-test
    "held, CI contains 0 %",
    "not held, CI excludes 0 %",
)
(HELD_SEPARATED, HELD_OVERLAP, NOT_HELD_OVERLAP, NOT_HELD_SEPARATED, NOT_HELD_BY_TEST,
 HELD_ZERO_IN_CI, NOT_HELD_ZERO_OUT) = CI_VERDICTS  # fmt: skip
_CONTRADICTED = (NOT_HELD_SEPARATED, NOT_HELD_ZERO_OUT)

_METRIC_WORDS = {"c": "the lowest mean c", "tau": "the fastest mean τ", "f": "the best mean f"}
_PAIR_CLAIMS = (
    ("SRL", "URL-R1", "the non-idiotypic seeded system (SRL) has a lower mean f than URL-R1."),
    ("UIE-R1", "URL-R1", "the idiotypic unseeded system UIE-R1 has a lower mean f than URL-R1."),
)


def _fmt(x: float) -> str:
    return f"{x:.1f}" if abs(x) >= 100 else f"{x:.2f}"


_FIELDS = ("id", "world", "text", "held", "evidence", "ci_held", "ci_verdict", "ci_evidence")


def _claim(
    cid: str, world: str | None, text: str, held: bool | None, evidence: str, ci: tuple = ()
) -> dict:
    """A ledger entry; ``ci = (ci_held, ci_verdict, ci_evidence)``, empty when not evaluated; a
    world's claim text opens with the world's name."""
    text = text if world is None else f"In {protocol.WORLD_NAMES[world]}, {text}"
    values = (cid, world, text, held, evidence, *(ci or (None, None, "")))
    return dict(zip(_FIELDS, values, strict=True))


def _ci_reading(held: bool, as_claimed: bool, against: bool, evidence: str) -> tuple:
    """``(ci_held, ci_verdict, ci_evidence)`` of a comparison: ``as_claimed`` when the intervals
    separate the way the claim says, ``against`` when some separate the other way."""
    if held:
        return as_claimed, HELD_SEPARATED if as_claimed else HELD_OVERLAP, evidence
    if against:
        return False, NOT_HELD_SEPARATED, evidence
    return False, NOT_HELD_BY_TEST if as_claimed else NOT_HELD_OVERLAP, evidence


def _ci(iv) -> str:
    return f"[{_fmt(float(iv[0]))}, {_fmt(float(iv[1]))}]"


def _missing(needed: Sequence[str], have: Sequence[str], world: str) -> str | None:
    """Why a claim cannot be evaluated (``None`` when every needed system has results)."""
    if not have:
        return f"No results for {world}."
    lacking = [s for s in needed if s not in have]
    return f"No results for {', '.join(lacking)} in {world}." if lacking else None


def _lowest(world: str, results: stats.Results, have: list[str], metric: str, cis: Mapping) -> dict:
    cid = f"{world}/SIE-lowest-{metric}"
    text = f"the seeded idiotypic system (SIE) has {_METRIC_WORDS[metric]}."
    others = [s for s in have if s != "SIE"]
    why = _missing(["SIE"], have, world) or (None if others else f"No other system in {world}.")
    if why:
        return _claim(cid, world, text, None, why)
    means = {s: float(stats.metric_values(results[s], metric).mean()) for s in have}
    sie = means.pop("SIE")
    best = min(means, key=means.__getitem__)
    held = all(sie <= v for v in means.values())
    tie = " (a tie)" if sie == means[best] else ""
    evidence = f"SIE {_fmt(sie)}; lowest other: {best} {_fmt(means[best])}{tie}"
    absent = [s for s in protocol.systems_for_world(world) if s not in have]
    if absent:
        evidence += f"; no results for {', '.join(absent)}"
    ci = {s: cis[s][metric] for s in have}
    nearest = min(others, key=lambda s: ci[s][0])  # the smallest lower bound
    below = min(others, key=lambda s: ci[s][1])  # the smallest upper bound
    as_claimed = stats.ci_below(ci["SIE"], ci[nearest])
    against = stats.ci_below(ci[below], ci["SIE"])
    shown = below if against else nearest
    ci_evidence = f"SIE {_ci(ci['SIE'])}; {shown} {_ci(ci[shown])}."
    reading = _ci_reading(held, as_claimed, against, ci_evidence)
    return _claim(cid, world, text, held, evidence + ".", reading)


def _no_failures(world: str, results: stats.Results, have: list[str]) -> dict:
    cid = f"{world}/SIE-no-failures"
    text = "SIE has a 0 % failure rate."
    why = _missing(["SIE"], have, world)
    if why:
        return _claim(cid, world, text, None, why)
    trials = results["SIE"]
    by_c, by_tau, failed = stats.failure_counts(trials).values()
    evidence = (
        f"{failed} of {len(trials)} SIE trials failed ({100 * failed / len(trials):.0f} %; "
        f"by c: {by_c}, by τ: {by_tau})."
    )
    lo, hi = stats.proportion_ci(failed, len(trials))
    ci_evidence = f"SIE failure rate [{100 * lo:.2g}, {100 * hi:.2g}] % (Wilson)."
    held = failed == 0
    reading = (held, HELD_ZERO_IN_CI if held else NOT_HELD_ZERO_OUT, ci_evidence)
    return _claim(cid, world, text, held, evidence, reading)


def _f_below(
    world: str, results: stats.Results, have: list[str], cis: Mapping, claim: tuple
) -> dict:
    """The claim ``(a, b, text, alpha)`` that a's mean f is lower than b's; with ``alpha`` (not
    None), significantly (two-tailed Student's t)."""
    a, b, text, alpha = claim
    cid = f"{world}/{a}-f-{'below' if alpha is None else 'sig-below'}/{b}"
    why = _missing([a, b], have, world)
    if why:
        return _claim(cid, world, text, None, why)
    fa, fb = (stats.metric_values(results[s], "f") for s in (a, b))
    held = bool(fa.mean() < fb.mean())
    evidence = f"{a} f {_fmt(fa.mean())} vs {b} {_fmt(fb.mean())}"
    if alpha is not None:
        _, p = stats.student_t(fa, fb)
        held = bool(held and p < alpha)
        evidence += f"; p={p:.2g} (level {stats.significance_level(p)})"
    ci_a, ci_b = cis[a]["f"], cis[b]["f"]
    as_claimed, against = stats.ci_below(ci_a, ci_b), stats.ci_below(ci_b, ci_a)
    reading = _ci_reading(held, as_claimed, against, f"{a} f {_ci(ci_a)} vs {b} {_ci(ci_b)}.")
    return _claim(cid, world, text, held, evidence + ".", reading)


def _world_claims(world: str, results: stats.Results, alpha: float, cis: Mapping) -> list[dict]:
    systems = protocol.systems_for_world(world)
    have = [s for s in systems if len(results.get(s, ())) > 0]
    out = [_lowest(world, results, have, m, cis) for m in stats.METRICS]
    out.append(_no_failures(world, results, have))
    level = f"two-tailed Student's t, {100 * (1 - alpha):g} % level"
    pairs = [
        ("SIE", u, f"SIE's f is significantly lower than {u}'s ({level}).", alpha)
        for u in protocol.UNSEEDED
        if u in systems
    ]
    pairs += [(a, b, text, None) for a, b, text in _PAIR_CLAIMS]
    out += [_f_below(world, results, have, cis, pair) for pair in pairs]
    return out


def _hypothesis_reading(h: str, verdict: Mapping[str, Any]) -> tuple:
    held, ci_held = bool(verdict["supported"]), bool(verdict["ci_supported"])
    if h == "H4":  # a 0 % claim: see the module docstring
        return ci_held, HELD_ZERO_IN_CI if held else NOT_HELD_ZERO_OUT, verdict["ci_summary"]
    if held:
        label = HELD_SEPARATED if ci_held else HELD_OVERLAP
    else:
        label = NOT_HELD_SEPARATED if verdict["ci_contradicted"] else NOT_HELD_OVERLAP
    return ci_held, label, verdict["ci_summary"]


def claims(
    results_by_world: stats.ResultsByWorld,
    alpha: float = protocol.ALPHA,
    cis: stats.CIs | None = None,
) -> list[dict]:
    """The 32 claims in order (world1, world2, real, H1-H4), each ``{"id", "world", "text",
    "held", "evidence", "ci_held", "ci_verdict", "ci_evidence"}``; other worlds count for H1-H4
    only; ``cis``: :func:`stats.table3_ci` (computed when None)."""
    cis = stats.table3_ci(results_by_world) if cis is None else cis
    out = []
    for world in protocol.WORLDS:
        out += _world_claims(world, results_by_world.get(world, {}), alpha, cis.get(world, {}))
    for h, verdict in stats.hypotheses(results_by_world, alpha, cis).items():
        testable = not verdict["summary"].startswith("Not testable")
        held = bool(verdict["supported"]) if testable else None
        reading = _hypothesis_reading(h, verdict) if testable else None
        text = f"{h} is supported: {HYPOTHESES[h]}"
        out.append(_claim(h, None, text, held, verdict["summary"], reading))
    return out


def by_rule(
    results_by_world: stats.ResultsByWorld,
    cap: int = protocol.COLLISION_CAP,
    alpha: float = protocol.ALPHA,
) -> dict[str, dict[str, Any]]:
    """The claims under every counting rule but the default that the records carry
    (:func:`stats.under_rule`; a run "failed on collisions" under a rule when its count under
    that rule exceeds ``cap``): ``{rule: document(ledger)}``, ``claims.json``'s ``"by_rule"``."""
    return {
        rule: document(claims(stats.under_rule(results_by_world, rule, cap), alpha))
        for rule in protocol.COUNTING_RULES[1:]
        if stats.has_rule(results_by_world, rule)
    }


def summary(ledger: Sequence[Mapping[str, Any]]) -> dict[str, int]:
    """``{"reproduced": claims held, "total": all claims, "evaluated": claims with data}``."""
    held = [c["held"] for c in ledger]
    return {
        "reproduced": sum(h is True for h in held),
        "total": len(held),
        "evaluated": sum(h is not None for h in held),
    }


def ci_summary(ledger: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """``{"reproduced", "reproduced_with_ci", "contradicted_with_ci" (separated the other way),
    "evaluated", "level"}``; entries without interval fields count as not held with them."""
    evaluated = [c for c in ledger if c["held"] is not None]
    return {
        "reproduced": sum(c["held"] is True for c in evaluated),
        "reproduced_with_ci": sum(c.get("ci_held") is True for c in evaluated),
        "contradicted_with_ci": sum(c.get("ci_verdict") in _CONTRADICTED for c in evaluated),
        "evaluated": len(evaluated),
        "level": stats.CI_LEVEL,
    }


def document(ledger: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """The ``claims.json`` document: ``{"summary", "ci_summary", "claims"}``."""
    return stats.jsonable(
        {"summary": summary(ledger), "ci_summary": ci_summary(ledger), "claims": list(ledger)}
    )


def headline(counts: Mapping[str, int]) -> str:
    """The report's opening line, ``**N of M of the paper's claims reproduced**`` (M evaluated)."""
    return f"**{counts['reproduced']} of {counts['evaluated']} of the paper's claims reproduced**"


def ci_headline(counts: Mapping[str, Any]) -> str:
    """How many claims hold, and how many are contradicted, with their intervals."""
    level = f"{100 * counts['level']:g} %"
    others = counts["evaluated"] - counts["reproduced"]
    return (
        f"With {level} confidence intervals: {counts['reproduced_with_ci']} of the "
        f"{counts['reproduced']} reproduced claims also hold with their intervals (separated, "
        f"or for a 0 % failure rate containing 0); {counts['contradicted_with_ci']} of the "
        f"{others} others are contradicted by them (separated the other way, or a failure "
        "rate's interval above 0); the rest are undecided at that level (intervals overlap)."
    )
