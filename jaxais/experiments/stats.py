"""Statistics of STL trials: the paper's Tables 3, 4 and 5, robustness tests and H1-H4 (SPEC 11).

Plain NumPy/SciPy, run outside jit on finished trial records. Lower is better for every metric
(c collisions, tau seconds, f = (rho c + tau) / 2), as in the paper. The worlds and systems (and
their order), Table 4's comparisons, the significance level and the collision cap are
:mod:`jaxais.experiments.protocol`'s.

A trial record is a dict (see :class:`TrialRecord`); the results of one world are
``dict[system_name, list[TrialRecord]]`` and ``results_by_world`` maps world names to those.
Failed trials are included in the means with their capped values, as the paper's Table 3 does:
c is the collision count capped at 100 (``collisions_capped``; the raw count can run to
thousands) and tau is capped at 4000 s by the run itself. A run can breach both caps (SPEC 9), so
Table 5's c and tau columns overlap. Records of the older schema (no ``collisions_capped``,
``failed_by`` a single string or ``None``) are still read.

Degenerate samples never raise or return NaN:

* a test is impossible when a group is too small to estimate its variance (Student: fewer than
  3 observations in all; Welch: fewer than 2 in a group): the test returns ``(0.0, 1.0)``,
  i.e. "no evidence of a difference";
* both groups have zero variance: identical means give ``(0.0, 1.0)``, different means give
  ``(+-inf, 0.0)`` (the limit of the statistic; the difference is certain);
* an empty group is a caller error and raises ``ValueError``.

:func:`jsonable` turns the infinities into ``None`` when results are written as JSON.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from typing import Any, Literal, TypedDict

import numpy as np
from scipy import stats as sps

from jaxais.experiments import protocol

__all__ = [
    "FAILURE_COLUMNS",
    "METRICS",
    "Results",
    "ResultsByWorld",
    "TrialRecord",
    "build_tables",
    "cohens_d",
    "comparison_pairs",
    "comparisons",
    "hypotheses",
    "idiotypic_difference_rates",
    "failure_causes",
    "jsonable",
    "mann_whitney_u",
    "metric_values",
    "significance_level",
    "student_t",
    "table3",
    "table4",
    "table5",
    "trapped_times",
    "welch_t",
]

METRICS: tuple[str, ...] = ("c", "tau", "f")
"""Table 3 / Table 4 metric keys."""
FAILURE_COLUMNS: tuple[str, ...] = ("c", "tau", "total")
"""Table 5 keys: failures by collision cap, by time cap, overall."""

_RECORD_KEY = {"tau": "tau", "f": "fitness"}


class TrialRecord(TypedDict):
    """One STL trial, as produced by the trial runner (SPEC 9).

    ``collisions`` is the raw count; ``collisions_capped = min(collisions, 100)`` and
    ``fitness = (8 collisions_capped + tau) / 2``. ``failed_by`` lists the caps breached (both
    may be): ``failed_collisions`` is ``collisions > 100``, ``failed_time`` a run that hit the
    4000 s cap, ``failed`` either. ``trapped_s`` is the simulated time spent trapped.
    """

    tau: float
    collisions: int
    collisions_capped: int
    fitness: float
    failed: bool
    failed_collisions: bool
    failed_time: bool
    failed_by: list[Literal["collisions", "time"]]
    trapped_s: float
    idiotypic_difference_rate: float | None
    iterations: int
    replaced: int


Results = Mapping[str, Sequence[Mapping[str, Any]]]
"""One world's trials: ``{system: [TrialRecord]}``."""
ResultsByWorld = Mapping[str, Results]
"""``{world: {system: [TrialRecord]}}``."""


# --------------------------------------------------------------------------- systems and pairs


def comparison_pairs(
    world: str, present: Iterable[str] | None = None
) -> tuple[tuple[str, str], ...]:
    """Table 4's comparisons for ``world``, in the paper's order.

    Args:
        world: world name; filters by :func:`~jaxais.experiments.protocol.systems_for_world`.
        present: if given, keep only pairs whose two systems are both in it (e.g. the systems
            with results).
    """
    allowed = set(protocol.systems_for_world(world))
    if present is not None:
        allowed &= set(present)
    return tuple((a, b) for a, b in protocol.COMPARISONS if a in allowed and b in allowed)


def _ordered_systems(results: Results) -> list[str]:
    """Systems with at least one trial: the paper's order first, then any others as given."""
    have = [s for s, trials in results.items() if len(trials) > 0]
    return [s for s in protocol.SYSTEMS if s in have] + [
        s for s in have if s not in protocol.SYSTEMS
    ]


def _capped_c(trial: Mapping[str, Any]) -> float:
    """``collisions_capped``, or ``min(collisions, 100)`` for records without it."""
    if "collisions_capped" in trial:
        return float(trial["collisions_capped"])
    return float(min(trial["collisions"], protocol.COLLISION_CAP))


def metric_values(trials: Sequence[Mapping[str, Any]], metric: str) -> np.ndarray:
    """Values of ``metric`` ("c", "tau" or "f") over ``trials``, float64 ``[n]``.

    "c" is the capped collision count (Table 3's, and the one in f), not the raw count.
    """
    if metric == "c":
        return np.asarray([_capped_c(t) for t in trials], dtype=np.float64)
    key = _RECORD_KEY[metric]
    return np.asarray([float(t[key]) for t in trials], dtype=np.float64)


def failure_causes(trial: Mapping[str, Any]) -> frozenset[str]:
    """The caps a trial breached: a subset of ``{"collisions", "time"}``.

    Read from ``failed_collisions`` / ``failed_time`` when present, else from ``failed_by``
    (a list, or the older single string or ``None``).
    """
    if "failed_collisions" in trial or "failed_time" in trial:
        flags = {"collisions": trial.get("failed_collisions"), "time": trial.get("failed_time")}
        return frozenset(k for k, v in flags.items() if v)
    by = trial.get("failed_by")
    if by is None:
        return frozenset()
    return frozenset([by] if isinstance(by, str) else by)


# --------------------------------------------------------------------------- tests


def _two_groups(a: Sequence[float], b: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
    x = np.asarray(a, dtype=np.float64).ravel()
    y = np.asarray(b, dtype=np.float64).ravel()
    if x.size == 0 or y.size == 0:
        raise ValueError("both groups need at least one observation")
    return x, y


def _t_result(diff: float, se2: float, df: float) -> tuple[float, float]:
    """t = diff / sqrt(se2) and its two-tailed p on ``df`` degrees of freedom, degenerate-safe."""
    if se2 <= 0.0:
        if diff == 0.0:
            return 0.0, 1.0
        return math.copysign(math.inf, diff), 0.0
    t = diff / math.sqrt(se2)
    return t, float(2.0 * sps.t.sf(abs(t), df))


def student_t(a: Sequence[float], b: Sequence[float]) -> tuple[float, float]:
    """Two-sample Student's t-test with pooled variance, two-tailed (the paper's test).

    ``t = (mean_a - mean_b) / sqrt(s_p^2 (1/n_a + 1/n_b))`` with
    ``s_p^2 = ((n_a - 1) s_a^2 + (n_b - 1) s_b^2) / (n_a + n_b - 2)`` on ``n_a + n_b - 2`` degrees
    of freedom.

    Returns:
        ``(t, p)``; ``(0.0, 1.0)`` when ``n_a + n_b < 3``; see the module docstring for zero
        variance.
    """
    x, y = _two_groups(a, b)
    df = x.size + y.size - 2
    if df < 1:
        return 0.0, 1.0
    ss = np.sum((x - x.mean()) ** 2) + np.sum((y - y.mean()) ** 2)
    pooled = float(ss) / df
    return _t_result(float(x.mean() - y.mean()), pooled * (1 / x.size + 1 / y.size), df)


def welch_t(a: Sequence[float], b: Sequence[float]) -> tuple[float, float]:
    """Welch's unequal-variance t-test, two-tailed.

    ``t = (mean_a - mean_b) / sqrt(s_a^2/n_a + s_b^2/n_b)`` with Welch-Satterthwaite degrees of
    freedom ``(s_a^2/n_a + s_b^2/n_b)^2 / ((s_a^2/n_a)^2/(n_a-1) + (s_b^2/n_b)^2/(n_b-1))``.

    Returns:
        ``(t, p)``; ``(0.0, 1.0)`` when a group has fewer than 2 observations; see the module
        docstring for zero variance.
    """
    x, y = _two_groups(a, b)
    if x.size < 2 or y.size < 2:
        return 0.0, 1.0
    va = float(x.var(ddof=1)) / x.size
    vb = float(y.var(ddof=1)) / y.size
    se2 = va + vb
    df = se2**2 / (va**2 / (x.size - 1) + vb**2 / (y.size - 1)) if se2 > 0 else 1.0
    return _t_result(float(x.mean() - y.mean()), se2, df)


def mann_whitney_u(a: Sequence[float], b: Sequence[float]) -> tuple[float, float]:
    """Two-sided Mann-Whitney U test (scipy's exact or tie-corrected asymptotic method).

    Returns:
        ``(U, p)`` where ``U`` counts the pairs with ``a_i > b_j`` plus half the ties (so small
        ``U`` means ``a`` tends to be lower). When every value is the same: ``(n_a n_b / 2, 1.0)``.
    """
    x, y = _two_groups(a, b)
    if np.all(np.concatenate([x, y]) == x[0]):
        return x.size * y.size / 2.0, 1.0
    res = sps.mannwhitneyu(x, y, alternative="two-sided")
    return float(res.statistic), float(res.pvalue)


def cohens_d(a: Sequence[float], b: Sequence[float]) -> float:
    """Cohen's d = (mean_a - mean_b) / pooled SD (the pooled SD of :func:`student_t`).

    Returns:
        d; ``0.0`` when ``n_a + n_b < 3`` or both means are equal with zero pooled SD, and
        ``+-inf`` when the pooled SD is zero but the means differ.
    """
    x, y = _two_groups(a, b)
    df = x.size + y.size - 2
    diff = float(x.mean() - y.mean())
    if df < 1:
        return 0.0
    pooled_sd = math.sqrt(float(np.sum((x - x.mean()) ** 2) + np.sum((y - y.mean()) ** 2)) / df)
    if pooled_sd == 0.0:
        return 0.0 if diff == 0.0 else math.copysign(math.inf, diff)
    return diff / pooled_sd


def significance_level(p: float) -> int:
    """The paper's Table 4 entry: ``100 (1 - p)`` rounded half up to an integer."""
    return int(math.floor(100.0 * (1.0 - float(p)) + 0.5))


# --------------------------------------------------------------------------- tables


def table3(results_by_world: ResultsByWorld) -> dict[str, dict[str, dict[str, float]]]:
    """Mean c, tau and f per world and system (the paper's Table 3).

    Returns:
        ``{world: {system: {"c": float, "tau": float, "f": float}}}``; systems without trials
        are left out.
    """
    out: dict[str, dict[str, dict[str, float]]] = {}
    for world, results in results_by_world.items():
        out[world] = {
            s: {m: float(metric_values(results[s], m).mean()) for m in METRICS}
            for s in _ordered_systems(results)
        }
    return out


def _failure_row(trials: Sequence[Mapping[str, Any]]) -> dict[str, float]:
    n = len(trials)
    causes = [failure_causes(t) for t in trials]
    failed = [bool(t.get("failed")) or bool(b) for t, b in zip(trials, causes, strict=True)]
    return {
        "c": 100.0 * sum("collisions" in b for b in causes) / n,
        "tau": 100.0 * sum("time" in b for b in causes) / n,
        "total": 100.0 * sum(failed) / n,
    }


def table5(results_by_world: ResultsByWorld) -> dict[str, dict[str, dict[str, float]]]:
    """Failure percentages per world and system (the paper's Table 5).

    ``"c"`` counts the trials failed by collisions (c > 100), ``"tau"`` those failed by time (the
    4000 s cap), ``"total"`` those failed by either (or marked ``failed``); see
    :func:`failure_causes`. A run can breach both caps, so c + tau may exceed total, as in the
    paper.

    Returns:
        ``{world: {system: {"c": %, "tau": %, "total": %}}}`` as floats in [0, 100].
    """
    return {
        world: {s: _failure_row(results[s]) for s in _ordered_systems(results)}
        for world, results in results_by_world.items()
    }


def _compare_metric(a: np.ndarray, b: np.ndarray) -> dict[str, float | int]:
    t, p = student_t(a, b)
    wt, wp = welch_t(a, b)
    u, up = mann_whitney_u(a, b)
    return {
        "n_a": int(a.size),
        "n_b": int(b.size),
        "mean_a": float(a.mean()),
        "mean_b": float(b.mean()),
        "mean_diff": float(a.mean() - b.mean()),
        "student_t": t,
        "student_p": p,
        "level": significance_level(p),
        "welch_t": wt,
        "welch_p": wp,
        "mwu_u": u,
        "mwu_p": up,
        "cohens_d": cohens_d(a, b),
    }


def comparisons(results_by_world: ResultsByWorld) -> dict[str, dict[str, dict[str, dict]]]:
    """Every Table 4 comparison with Student's, Welch's and Mann-Whitney tests and Cohen's d.

    Only pairs whose systems both belong to the world and have trials are included.

    Returns:
        ``{world: {"A vs B": {metric: {"n_a", "n_b", "mean_a", "mean_b", "mean_diff",
        "student_t", "student_p", "level", "welch_t", "welch_p", "mwu_u", "mwu_p",
        "cohens_d"}}}}`` with ``mean_diff = mean_a - mean_b`` (negative: A is better) and
        ``level = significance_level(student_p)``. Statistics may be ``+-inf`` (zero variance).
    """
    out: dict[str, dict[str, dict[str, dict]]] = {}
    for world, results in results_by_world.items():
        out[world] = {
            f"{a} vs {b}": {
                m: _compare_metric(metric_values(results[a], m), metric_values(results[b], m))
                for m in METRICS
            }
            for a, b in comparison_pairs(world, _ordered_systems(results))
        }
    return out


def table4(results_by_world: ResultsByWorld) -> dict[str, dict[str, dict[str, int]]]:
    """Significance levels ``100 (1 - p)`` of two-tailed Student's t-tests (the paper's Table 4).

    Returns:
        ``{world: {"A vs B": {"c": int, "tau": int, "f": int}}}`` in the paper's row order.
    """
    return {
        world: {pair: {m: row[m]["level"] for m in METRICS} for pair, row in by_pair.items()}
        for world, by_pair in comparisons(results_by_world).items()
    }


def idiotypic_difference_rates(results_by_world: ResultsByWorld) -> dict[str, dict[str, Any]]:
    """Mean idiotypic difference rate per world and system, over trials that report one.

    Returns:
        ``{world: {system: float | None}}``; ``None`` when no trial has a rate (non-idiotypic
        systems). The unit is whatever the trial records hold.
    """
    out: dict[str, dict[str, Any]] = {}
    for world, results in results_by_world.items():
        row: dict[str, Any] = {}
        for s in _ordered_systems(results):
            rates = [t.get("idiotypic_difference_rate") for t in results[s]]
            rates = [float(r) for r in rates if r is not None]
            row[s] = float(np.mean(rates)) if rates else None
        out[world] = row
    return out


def trapped_times(results_by_world: ResultsByWorld) -> dict[str, dict[str, float | None]]:
    """Mean simulated time spent trapped (``trapped_s``, seconds) per world and system.

    Returns:
        ``{world: {system: float | None}}``; ``None`` when no trial of the system records it.
    """
    out: dict[str, dict[str, float | None]] = {}
    for world, results in results_by_world.items():
        row: dict[str, float | None] = {}
        for s in _ordered_systems(results):
            values = [float(t["trapped_s"]) for t in results[s] if t.get("trapped_s") is not None]
            row[s] = float(np.mean(values)) if values else None
        out[world] = row
    return out


# --------------------------------------------------------------------------- hypotheses


def _fmt(x: float) -> str:
    if not math.isfinite(x):
        return str(x)
    if abs(x) >= 100:
        return f"{x:.0f}"
    return f"{x:.1f}" if abs(x) >= 10 else f"{x:.2f}"


def _p(p: float) -> str:
    return f"p={p:.2g}"


def _worlds(results_by_world: ResultsByWorld, needed: Iterable[str]) -> list[str]:
    """Worlds (paper order first) whose results have trials for every system in ``needed``."""
    names = [w for w in protocol.WORLDS if w in results_by_world]
    names += [w for w in results_by_world if w not in protocol.WORLDS]
    return [w for w in names if set(needed) <= set(_ordered_systems(results_by_world[w]))]


def _f(results: Results, system: str) -> np.ndarray:
    return metric_values(results[system], "f")


def _h1(results_by_world: ResultsByWorld, alpha: float) -> dict[str, Any]:
    rule = (
        "Rule: in every world with SIE and unseeded results, each seeded system has a lower mean f "
        "than each unseeded system with the same selection (SIE < UIE-*, SRL < URL-*) and SIE's f "
        f"is significantly lower than every unseeded system's (Student's t, p < {alpha:g})."
    )
    worlds = [
        w
        for w in _worlds(results_by_world, ["SIE"])
        if any(s in _ordered_systems(results_by_world[w]) for s in protocol.UNSEEDED)
    ]
    if not worlds:
        return _untestable("no world has SIE and unseeded")
    fails, parts = [], []
    for w in worlds:
        res = results_by_world[w]
        have = _ordered_systems(res)
        unseeded = [s for s in protocol.UNSEEDED if s in have]
        mean = {s: float(_f(res, s).mean()) for s in have}
        worst_p = 0.0
        for u in unseeded:
            # SIE < UIE-* is implied by the significance check below.
            if u.startswith("URL") and "SRL" in have and not mean["SRL"] < mean[u]:
                fails.append(f"{w}: SRL f {_fmt(mean['SRL'])} >= {u} {_fmt(mean[u])}")
            _, p = student_t(_f(res, "SIE"), _f(res, u))
            worst_p = max(worst_p, p)
            if not mean["SIE"] < mean[u]:
                fails.append(f"{w}: SIE f {_fmt(mean['SIE'])} >= {u} {_fmt(mean[u])} ({_p(p)})")
            elif not p < alpha:
                fails.append(f"{w}: SIE vs {u} lower but not significantly ({_p(p)})")
        lo, hi = min(mean[u] for u in unseeded), max(mean[u] for u in unseeded)
        srl = f", SRL {_fmt(mean['SRL'])}" if "SRL" in have else ""
        parts.append(
            f"{w}: SIE f {_fmt(mean['SIE'])}{srl} vs unseeded {_fmt(lo)}-{_fmt(hi)} "
            f"(SIE vs unseeded max {_p(worst_p)})"
        )
    return _verdict(not fails, rule, parts, fails)


def _beats(results_by_world: ResultsByWorld, other: str, alpha: float) -> dict[str, Any]:
    """SIE has a lower mean f than ``other`` in every world, significantly in a strict majority."""
    rule = (
        f"Rule: SIE's mean f is lower than {other}'s in every world tested, and significantly "
        f"lower (Student's t, p < {alpha:g}) in a strict majority of those worlds."
    )
    worlds = _worlds(results_by_world, ["SIE", other])
    if not worlds:
        return _untestable(f"no world has SIE and {other}")
    fails, parts, n_sig = [], [], 0
    for w in worlds:
        a, b = _f(results_by_world[w], "SIE"), _f(results_by_world[w], other)
        _, p = student_t(a, b)
        lower = a.mean() < b.mean()
        n_sig += bool(lower and p < alpha)
        if not lower:
            fails.append(f"{w}: SIE f {_fmt(a.mean())} >= {other} {_fmt(b.mean())}")
        parts.append(
            f"{w}: SIE f {_fmt(a.mean())} vs {other} {_fmt(b.mean())} "
            f"({_p(p)}, level {significance_level(p)})"
        )
    if 2 * n_sig <= len(worlds):
        fails.append(f"significant in only {n_sig} of {len(worlds)} worlds")
    parts.append(f"significant in {n_sig} of {len(worlds)} worlds")
    return _verdict(not fails, rule, parts, fails)


def _h4(results_by_world: ResultsByWorld) -> dict[str, Any]:
    rule = "Rule: SIE (no antibody replacement) has 0 failed trials in every world tested."
    worlds = _worlds(results_by_world, ["SIE"])
    if not worlds:
        return _untestable("no SIE results")
    parts, fails = [], []
    for w in worlds:
        row = _failure_row(results_by_world[w]["SIE"])
        n = len(results_by_world[w]["SIE"])
        parts.append(f"{w}: {row['total']:.0f} % of {n} trials failed")
        if row["total"] > 0:
            fails.append(f"{w}: {row['total']:.0f} % failures")
    return _verdict(not fails, rule, parts, fails)


def _untestable(why: str) -> dict[str, Any]:
    text = f"Not testable: {why}."
    return {"supported": False, "evidence": text, "summary": text}


def _verdict(ok: bool, rule: str, parts: list[str], fails: list[str]) -> dict[str, Any]:
    head = "Supported." if ok else "Not supported."
    summary = "; ".join(parts) + "."
    if fails:
        summary += " Violations: " + "; ".join(fails) + "."
    return {"supported": ok, "evidence": f"{head} {rule} {summary}", "summary": summary}


def hypotheses(results_by_world: ResultsByWorld, alpha: float = protocol.ALPHA) -> dict[str, dict]:
    """Verdicts on the paper's hypotheses H1-H4 (section 2), judged on fitness f.

    Worlds missing from the results (or lacking the systems a rule needs) are skipped; a
    hypothesis with no world to test is "not supported" with evidence "Not testable".
    "Significantly lower" means a lower mean and a two-tailed Student's t p-value below
    ``alpha`` (the paper's 99 % level for the default 0.01).

    * **H1** (seeded beats unseeded): in every world, each seeded system has a lower mean f than
      each unseeded system with the same selection mechanism (SIE < UIE-R1/R2, SRL <
      URL-R1/R2) and SIE's f is significantly lower than every unseeded system's.
    * **H2** (SIE beats SRL) and **H3** (SIE beats HDC): SIE's mean f is lower in every world,
      and significantly lower in a strict majority of the worlds tested (2 of 3 for the paper's
      worlds; on the paper's own numbers H2 is significant in 2 of 3 worlds, H3 in 2 of 3).
    * **H4** (no replacement needed when seeded): SIE has no failed trial in any world.

    Returns:
        ``{"H1": {"supported": bool, "evidence": str, "summary": str}, ..., "H4": {...}}``; the
        evidence states the verdict, the rule, the per-world numbers and any violations; the
        summary only the numbers and violations (it starts "Not testable" when untestable).
    """
    return {
        "H1": _h1(results_by_world, alpha),
        "H2": _beats(results_by_world, "SRL", alpha),
        "H3": _beats(results_by_world, "HDC", alpha),
        "H4": _h4(results_by_world),
    }


# --------------------------------------------------------------------------- assembly


def jsonable(obj: Any) -> Any:
    """A copy of ``obj`` with plain Python types only: numpy scalars and arrays converted,
    tuples as lists, non-finite floats as ``None``."""
    if isinstance(obj, Mapping):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    if isinstance(obj, bool | np.bool_):
        return bool(obj)
    if isinstance(obj, int | np.integer):
        return int(obj)
    if isinstance(obj, float | np.floating):
        return float(obj) if math.isfinite(obj) else None
    return obj


def build_tables(results_by_world: ResultsByWorld, alpha: float = protocol.ALPHA) -> dict[str, Any]:
    """All of the report's tables, JSON-serialisable.

    Returns:
        ``{"table3": table3(...), "table4": table4(...), "table5": table5(...),
        "idiotypic_difference_rate": idiotypic_difference_rates(...),
        "trapped_s": trapped_times(...), "hypotheses": hypotheses(..., alpha)}``.
    """
    return jsonable(
        {
            "table3": table3(results_by_world),
            "table4": table4(results_by_world),
            "table5": table5(results_by_world),
            "idiotypic_difference_rate": idiotypic_difference_rates(results_by_world),
            "trapped_s": trapped_times(results_by_world),
            "hypotheses": hypotheses(results_by_world, alpha),
        }
    )
