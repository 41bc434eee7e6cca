"""The paper's 32 qualitative claims, checked one by one against our results (the claims ledger).

Per world (Simulated World 1, Simulated World 2, the real world), from the paper's section 6:

1. SIE has the lowest mean c, 2. the lowest mean tau, 3. the lowest mean f;
4. SIE has a 0 % failure rate;
5. SIE's f is significantly lower than each unseeded system's (one claim per unseeded system:
   four in each simulated world, two in the real world);
6. SRL has a lower mean f than URL-R1; 7. UIE-R1 has a lower mean f than URL-R1.

That is 10 + 10 + 8 = 28 claims, plus H1-H4 "supported" as decided by
:func:`jaxais.experiments.stats.hypotheses`: 32 in all.

Rules. "Lowest" compares SIE with the other systems of the world that have results and allows
ties (SIE's mean <= every other mean): the paper calls SIE's c lowest in Simulated World 2 where
HDC ties it at 2. "Lower" between two systems is strict. "Significantly lower" is a lower mean
and a two-tailed Student's t p-value below ``alpha`` (the paper's 99 % level for 0.01). Means use
the capped c (Table 3's). A claim whose world or systems have no results is not evaluated
(``held`` is ``None``); so is a hypothesis that :func:`~jaxais.experiments.stats.hypotheses` finds
not testable. The worlds, their systems and the significance level are
:mod:`jaxais.experiments.protocol`'s.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from . import protocol, stats

__all__ = ["HYPOTHESES", "claims", "document", "headline", "summary"]

HYPOTHESES = {
    "H1": "Seeded STL systems outperform unseeded STL systems.",
    "H2": "Seeded STL systems that employ idiotypic effects outperform seeded systems that do not.",
    "H3": "Seeded STL systems that employ idiotypic effects outperform fixed, hand-designed "
    "strategies.",
    "H4": "As long as the LTL-derived behaviours are sufficiently diverse, antibody replacement "
    "should not be necessary in the STL phase.",
}
"""The paper's hypotheses (section 2), verbatim."""

_METRIC_WORDS = {"c": "the lowest mean c", "tau": "the fastest mean τ", "f": "the best mean f"}
_PAIR_CLAIMS = (
    ("SRL", "URL-R1", "the non-idiotypic seeded system (SRL) has a lower mean f than URL-R1."),
    ("UIE-R1", "URL-R1", "the idiotypic unseeded system UIE-R1 has a lower mean f than URL-R1."),
)


def _fmt(x: float) -> str:
    return f"{x:.1f}" if abs(x) >= 100 else f"{x:.2f}"


def _claim(cid: str, world: str | None, text: str, held: bool | None, evidence: str) -> dict:
    return {"id": cid, "world": world, "text": text, "held": held, "evidence": evidence}


def _missing(needed: Sequence[str], have: Sequence[str], world: str) -> str | None:
    """Why a claim cannot be evaluated (``None`` when every needed system has results)."""
    if not have:
        return f"No results for {world}."
    lacking = [s for s in needed if s not in have]
    return f"No results for {', '.join(lacking)} in {world}." if lacking else None


def _mean(results: stats.Results, system: str, metric: str) -> float:
    return float(stats.metric_values(results[system], metric).mean())


# --------------------------------------------------------------------------- per-world claims


def _lowest(world: str, results: stats.Results, have: list[str], metric: str) -> dict:
    cid = f"{world}/SIE-lowest-{metric}"
    text = (
        f"In {protocol.WORLD_NAMES[world]}, the seeded idiotypic system (SIE) has "
        f"{_METRIC_WORDS[metric]}."
    )
    others = [s for s in have if s != "SIE"]
    why = _missing(["SIE"], have, world) or (None if others else f"No other system in {world}.")
    if why:
        return _claim(cid, world, text, None, why)
    sie = _mean(results, "SIE", metric)
    means = {s: _mean(results, s, metric) for s in others}
    best = min(means, key=means.__getitem__)
    held = all(sie <= v for v in means.values())
    tie = " (a tie)" if sie == means[best] else ""
    evidence = f"SIE {_fmt(sie)}; lowest other: {best} {_fmt(means[best])}{tie}"
    absent = [s for s in protocol.systems_for_world(world) if s not in have]
    if absent:
        evidence += f"; no results for {', '.join(absent)}"
    return _claim(cid, world, text, held, evidence + ".")


def _no_failures(world: str, results: stats.Results, have: list[str]) -> dict:
    cid = f"{world}/SIE-no-failures"
    text = f"In {protocol.WORLD_NAMES[world]}, SIE has a 0 % failure rate."
    why = _missing(["SIE"], have, world)
    if why:
        return _claim(cid, world, text, None, why)
    trials = results["SIE"]
    causes = [stats.failure_causes(t) for t in trials]
    failed = sum(bool(t.get("failed")) or bool(b) for t, b in zip(trials, causes, strict=True))
    by_c = sum("collisions" in b for b in causes)
    by_tau = sum("time" in b for b in causes)
    evidence = (
        f"{failed} of {len(trials)} SIE trials failed ({100 * failed / len(trials):.0f} %; "
        f"by c: {by_c}, by τ: {by_tau})."
    )
    return _claim(cid, world, text, failed == 0, evidence)


def _sig_below(
    world: str, results: stats.Results, have: list[str], other: str, alpha: float
) -> dict:
    cid = f"{world}/SIE-f-sig-below/{other}"
    text = (
        f"In {protocol.WORLD_NAMES[world]}, SIE's f is significantly lower than {other}'s "
        f"(two-tailed Student's t, {100 * (1 - alpha):g} % level)."
    )
    why = _missing(["SIE", other], have, world)
    if why:
        return _claim(cid, world, text, None, why)
    a = stats.metric_values(results["SIE"], "f")
    b = stats.metric_values(results[other], "f")
    _, p = stats.student_t(a, b)
    held = bool(a.mean() < b.mean() and p < alpha)
    evidence = (
        f"SIE f {_fmt(a.mean())} vs {other} {_fmt(b.mean())}; p={p:.2g} "
        f"(level {stats.significance_level(p)})."
    )
    return _claim(cid, world, text, held, evidence)


def _lower(world: str, results: stats.Results, have: list[str], a: str, b: str, text: str) -> dict:
    cid = f"{world}/{a}-f-below/{b}"
    text = f"In {protocol.WORLD_NAMES[world]}, {text}"
    why = _missing([a, b], have, world)
    if why:
        return _claim(cid, world, text, None, why)
    fa, fb = _mean(results, a, "f"), _mean(results, b, "f")
    return _claim(cid, world, text, fa < fb, f"{a} f {_fmt(fa)} vs {b} {_fmt(fb)}.")


def _world_claims(world: str, results: stats.Results, alpha: float) -> list[dict]:
    systems = protocol.systems_for_world(world)
    have = [s for s in systems if len(results.get(s, ())) > 0]
    out = [_lowest(world, results, have, m) for m in stats.METRICS]
    out.append(_no_failures(world, results, have))
    out += [_sig_below(world, results, have, u, alpha) for u in protocol.UNSEEDED if u in systems]
    out += [_lower(world, results, have, a, b, text) for a, b, text in _PAIR_CLAIMS]
    return out


# --------------------------------------------------------------------------- public


def claims(results_by_world: stats.ResultsByWorld, alpha: float = protocol.ALPHA) -> list[dict]:
    """The paper's 32 claims, each judged on our results (see the module docstring for rules).

    Args:
        results_by_world: ``{world: {system: [trial record]}}``; worlds other than the paper's
            three count only for H1-H4.
        alpha: significance threshold of the t-tests (the paper's 0.01).

    Returns:
        32 dicts ``{"id": str, "world": str | None, "text": str, "held": bool | None,
        "evidence": str}`` in a fixed order: world1, world2, real (10, 10, 8 claims), then
        H1-H4. ``held`` is ``None`` when the claim's data are missing.
    """
    out = []
    for world in protocol.WORLDS:
        out += _world_claims(world, results_by_world.get(world, {}), alpha)
    for h, verdict in stats.hypotheses(results_by_world, alpha).items():
        testable = not verdict["summary"].startswith("Not testable")
        held = bool(verdict["supported"]) if testable else None
        out.append(_claim(h, None, f"{h} is supported: {HYPOTHESES[h]}", held, verdict["summary"]))
    return out


def summary(ledger: Sequence[Mapping[str, Any]]) -> dict[str, int]:
    """``{"reproduced": claims held, "total": all claims, "evaluated": claims with data}``."""
    held = [c["held"] for c in ledger]
    return {
        "reproduced": sum(h is True for h in held),
        "total": len(held),
        "evaluated": sum(h is not None for h in held),
    }


def document(ledger: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """The ``claims.json`` document: ``{"summary": summary(ledger), "claims": [...]}``."""
    return stats.jsonable({"summary": summary(ledger), "claims": list(ledger)})


def headline(counts: Mapping[str, int]) -> str:
    """The report's opening line, ``**N of M of the paper's claims reproduced**``.

    M counts the evaluated claims only; :func:`summary` gives the counts.
    """
    return f"**{counts['reproduced']} of {counts['evaluated']} of the paper's claims reproduced**"
