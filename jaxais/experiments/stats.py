"""Statistics of STL trials: the paper's Tables 3-5, robustness tests and H1-H4 (SPEC 11).

Plain NumPy/SciPy on finished trial records (``{world: {system: [record]}}``); lower is
better for c, tau and f. Means use capped values, as the paper's Table 3 does [paper]. Degenerate
samples never raise or give NaN: a test without a variance estimate gives ``(0.0, 1.0)``, zero
variance with different means ``(+-inf, 0.0)``; an empty group raises ValueError. Means get 95 %
percentile bootstrap intervals drawn from ``(seed, crc32(world), crc32(system))``, so an interval
depends on that system's trials only; failure rates get Wilson intervals, informative at 0 of n
[ours].
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np
from scipy import stats as sps

from jaxais.experiments import protocol

__all__ = [
    "BOOTSTRAP_RESAMPLES",
    "BOOTSTRAP_SEED",
    "CI_LEVEL",
    "CIs",
    "FAILURE_COLUMNS",
    "METRICS",
    "Results",
    "ResultsByWorld",
    "bootstrap_mean_ci",
    "build_tables",
    "ci_below",
    "cohens_d",
    "comparison_pairs",
    "comparisons",
    "contender_tables",
    "failure_counts",
    "hypotheses",
    "in_order",
    "jsonable",
    "mann_whitney_u",
    "metric_values",
    "proportion_ci",
    "has_rule",
    "record_means",
    "rule_tables",
    "under_rule",
    "significance_level",
    "student_t",
    "table3",
    "table3_ci",
    "table4",
    "table5",
    "table5_ci",
    "calibration",
    "welch_t",
]

METRICS: tuple[str, ...] = ("c", "tau", "f")
"""Table 3 / Table 4 metric keys."""
FAILURE_COLUMNS: tuple[str, ...] = ("c", "tau", "total")
"""Table 5 keys: failures by collision cap, by time cap, overall."""

_RECORD_KEY = {"c": "collisions_capped", "tau": "tau", "f": "fitness"}
_FAILED_KEY = {"c": "failed_collisions", "tau": "failed_time", "total": "failed"}
_MEANS = ("idiotypic_difference_rate", "trapped_s", "locked_s")
"""Record fields whose per-system means the tables hold."""

CI_LEVEL = 0.95
BOOTSTRAP_RESAMPLES = 2000
"""B >= 1000 for percentile intervals (Efron & Tibshirani 1993, ch. 19)."""
BOOTSTRAP_SEED = 0
_CI_SETTINGS = {
    "level": CI_LEVEL,
    "table3": "percentile bootstrap of the mean; a system's trials resampled with "
    "replacement, c, tau and f together",
    "resamples": BOOTSTRAP_RESAMPLES,
    "seed": BOOTSTRAP_SEED,
    "table5": "Wilson score interval of the proportion, in %",
}
"""How the tables' intervals were made (``tables.json``'s ``"ci"``)."""


Results = Mapping[str, Sequence[Mapping[str, Any]]]
"""One world's trials: ``{system: [trial record]}`` (SPEC 9, :mod:`.records`)."""
ResultsByWorld = Mapping[str, Results]

CIs = Mapping[str, Mapping[str, Mapping[str, Sequence[float]]]]
"""``{world: {system: {metric: [lo, hi]}}}`` (:func:`table3_ci`)."""


def comparison_pairs(
    world: str, present: Iterable[str] | None = None
) -> tuple[tuple[str, str], ...]:
    """Table 4's comparisons of ``world``'s systems (both in ``present`` when given), in order."""
    allowed = set(protocol.systems_for_world(world))
    if present is not None:
        allowed &= set(present)
    return tuple((a, b) for a, b in protocol.COMPARISONS if a in allowed and b in allowed)


def in_order(names: Iterable[str], order: Sequence[str]) -> list[str]:
    """``names`` without repeats: those in ``order`` first, in that order, then the rest."""
    unique = list(dict.fromkeys(names))
    return [n for n in order if n in unique] + [n for n in unique if n not in order]


def _ordered_systems(results: Results) -> list[str]:
    """Systems with at least one trial, in the paper's order."""
    return in_order([s for s, trials in results.items() if len(trials) > 0], protocol.SYSTEMS)


def under_rule(
    results_by_world: ResultsByWorld, rule: str, cap: int = protocol.COLLISION_CAP
) -> dict[str, dict[str, list[dict[str, Any]]]]:
    """The trials as if c were counted by ``rule`` (:data:`protocol.COUNTING_RULES`): each
    record's ``collisions``, ``collisions_capped`` (at ``cap``), ``fitness``,
    ``failed_collisions`` (c > cap), ``failed`` and ``failed_by`` from its
    ``collisions_<rule>``; τ and the time cap's failures unchanged. The default rule gives the
    records as they are. ValueError naming the first record without that count."""
    if rule not in protocol.COUNTING_RULES:
        raise ValueError(f"rule must be one of {', '.join(protocol.COUNTING_RULES)}, got {rule!r}")
    if rule == protocol.DEFAULT_RULE:
        return {w: {s: list(t) for s, t in r.items()} for w, r in results_by_world.items()}
    key = f"collisions_{rule}"

    def view(world: str, system: str, record: Mapping[str, Any]) -> dict[str, Any]:
        if key not in record:
            raise ValueError(
                f"{world} {system}: a trial record without {key!r} (made before c was counted "
                "by each rule): run its trials again"
            )
        c = int(record[key])
        capped = min(c, cap)
        by_c, by_t = c > cap, bool(record["failed_time"])
        return dict(record) | {
            "collisions": c,
            "collisions_capped": capped,
            "fitness": (protocol.RHO * capped + float(record["tau"])) / 2.0,
            "failed": by_c or by_t,
            "failed_collisions": by_c,
            "failed_by": [n for n, on in (("collisions", by_c), ("time", by_t)) if on],
        }

    return {
        w: {s: [view(w, s, r) for r in trials] for s, trials in results.items()}
        for w, results in results_by_world.items()
    }


def has_rule(results_by_world: ResultsByWorld, rule: str) -> bool:
    """Whether every trial records its c under ``rule``."""
    key = f"collisions_{rule}"
    return rule == protocol.DEFAULT_RULE or all(
        key in r for results in results_by_world.values() for t in results.values() for r in t
    )


def rule_tables(
    results_by_world: ResultsByWorld,
    cap: int = protocol.COLLISION_CAP,
    alpha: float = protocol.ALPHA,
) -> dict[str, Any]:
    """Tables 3-5 with intervals and H1-H4 under every rule but the default that the records
    carry: ``{rule: {"table3", "table3_ci", "table4", "table5", "table5_ci", "hypotheses"}}``."""
    out = {}
    for rule in protocol.COUNTING_RULES[1:]:
        if has_rule(results_by_world, rule):
            view = under_rule(results_by_world, rule, cap)
            cis = table3_ci(view)
            tables = {"table3": table3(view), "table3_ci": cis, "table4": table4(view)}
            tables |= {"table5": table5(view), "table5_ci": table5_ci(view)}
            out[rule] = jsonable(tables | {"hypotheses": hypotheses(view, alpha, cis)})
    return out


def metric_values(trials: Sequence[Mapping[str, Any]], metric: str) -> np.ndarray:
    """``metric`` ("c" capped, "tau" or "f") over ``trials``, float64 ``[n]``."""
    return np.asarray([float(t[_RECORD_KEY[metric]]) for t in trials], dtype=np.float64)


def failure_counts(trials: Sequence[Mapping[str, Any]]) -> dict[str, int]:
    """Trials failed ``{"c": by collisions, "tau": by time, "total": by either}``."""
    return {k: sum(bool(t[key]) for t in trials) for k, key in _FAILED_KEY.items()}


def _two_groups(a: Sequence[float], b: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
    x, y = (np.asarray(g, dtype=np.float64).ravel() for g in (a, b))
    if x.size == 0 or y.size == 0:
        raise ValueError("both groups need at least one observation")
    return x, y


def _t_result(diff: float, se2: float, df: float) -> tuple[float, float]:
    """t = diff / sqrt(se2) and its two-tailed p on ``df`` degrees of freedom, degenerate-safe."""
    if se2 <= 0.0:
        return (0.0, 1.0) if diff == 0.0 else (math.copysign(math.inf, diff), 0.0)
    t = diff / math.sqrt(se2)
    return t, float(2.0 * sps.t.sf(abs(t), df))


def _pooled_var(x: np.ndarray, y: np.ndarray) -> float:
    """``((n_a - 1) s_a^2 + (n_b - 1) s_b^2) / (n_a + n_b - 2)``; the caller checks df >= 1."""
    ss = np.sum((x - x.mean()) ** 2) + np.sum((y - y.mean()) ** 2)
    return float(ss) / (x.size + y.size - 2)


def student_t(a: Sequence[float], b: Sequence[float]) -> tuple[float, float]:
    """Two-sample pooled-variance Student's t, two-tailed (the paper's test): ``(t, p)``;
    ``(0.0, 1.0)`` when ``n_a + n_b < 3``."""
    x, y = _two_groups(a, b)
    df = x.size + y.size - 2
    if df < 1:
        return 0.0, 1.0
    return _t_result(float(x.mean() - y.mean()), _pooled_var(x, y) * (1 / x.size + 1 / y.size), df)


def welch_t(a: Sequence[float], b: Sequence[float]) -> tuple[float, float]:
    """Welch's unequal-variance t, two-tailed, Welch-Satterthwaite df: ``(t, p)``;
    ``(0.0, 1.0)`` when a group has fewer than 2 observations."""
    x, y = _two_groups(a, b)
    if x.size < 2 or y.size < 2:
        return 0.0, 1.0
    va, vb = (float(g.var(ddof=1)) / g.size for g in (x, y))
    se2 = va + vb
    df = se2**2 / (va**2 / (x.size - 1) + vb**2 / (y.size - 1)) if se2 > 0 else 1.0
    return _t_result(float(x.mean() - y.mean()), se2, df)


def mann_whitney_u(a: Sequence[float], b: Sequence[float]) -> tuple[float, float]:
    """Two-sided Mann-Whitney U (scipy's method): ``(U, p)``, U counting pairs with
    ``a_i > b_j`` plus half the ties; ``(n_a n_b / 2, 1.0)`` when every value is the same."""
    x, y = _two_groups(a, b)
    if np.all(np.concatenate([x, y]) == x[0]):
        return x.size * y.size / 2.0, 1.0
    res = sps.mannwhitneyu(x, y, alternative="two-sided")
    return float(res.statistic), float(res.pvalue)


def cohens_d(a: Sequence[float], b: Sequence[float]) -> float:
    """(mean_a - mean_b) / pooled SD; 0.0 when ``n_a + n_b < 3`` or nothing differs, ``+-inf``
    for different means with zero SD."""
    x, y = _two_groups(a, b)
    diff = float(x.mean() - y.mean())
    if x.size + y.size < 3:
        return 0.0
    pooled_sd = math.sqrt(_pooled_var(x, y))
    if pooled_sd == 0.0:
        return 0.0 if diff == 0.0 else math.copysign(math.inf, diff)
    return diff / pooled_sd


def significance_level(p: float) -> int:
    """The paper's Table 4 entry: ``100 (1 - p)`` rounded half up to an integer."""
    return int(math.floor(100.0 * (1.0 - float(p)) + 0.5))


def bootstrap_mean_ci(
    values: Sequence[float] | np.ndarray,
    level: float = CI_LEVEL,
    resamples: int = BOOTSTRAP_RESAMPLES,
    rng: np.random.Generator | int | None = BOOTSTRAP_SEED,
) -> tuple[np.ndarray, np.ndarray]:
    """Percentile bootstrap interval of the mean of ``values`` ``[n]`` or ``[n, k]`` (the k
    columns resampled together), scipy's draw ``rng.integers(0, n, (resamples, n))`` and
    ``np.quantile``'s interpolation: ``(lo, hi)`` of shape ``[]`` or ``[k]``, ``[x, x]`` for a
    constant sample. ValueError on no values, a level outside (0, 1) or resamples < 1."""
    x = np.asarray(values, dtype=np.float64)
    if x.ndim not in (1, 2) or x.shape[0] == 0:
        raise ValueError(f"need [n] or [n, k] values with n >= 1, got shape {x.shape}")
    if not 0.0 < level < 1.0:
        raise ValueError(f"level must be in (0, 1), got {level}")
    if resamples < 1:
        raise ValueError(f"resamples must be >= 1, got {resamples}")
    rng = np.random.default_rng(rng)
    idx = rng.integers(0, x.shape[0], (resamples, x.shape[0]))  # [B, n]
    columns = x[:, None] if x.ndim == 1 else x
    # One column at a time: a [B, n] gather each, not [B, n, k].
    means = np.stack([col[idx].mean(axis=1) for col in columns.T], axis=-1)  # [B, k]
    tail = (1.0 - level) / 2.0
    # Every resample's mean lies in [min, max]; clipping only removes rounding (a constant
    # sample's summed means can miss x by an ulp), so zero variance gives exactly [x, x].
    lo, hi = np.clip(
        np.quantile(means, [tail, 1.0 - tail], axis=0), columns.min(axis=0), columns.max(axis=0)
    )
    if x.ndim == 1:
        return lo[0], hi[0]
    return lo, hi


def proportion_ci(successes: int, n: int, level: float = CI_LEVEL) -> tuple[float, float]:
    """Wilson score interval of ``successes / n`` in [0, 1] (``[0, z^2 / (n + z^2)]`` at 0);
    ValueError on n < 1, successes outside [0, n] or a level outside (0, 1)."""
    if n < 1 or not 0 <= successes <= n:
        raise ValueError(f"need 0 <= successes <= n and n >= 1, got {successes} of {n}")
    if not 0.0 < level < 1.0:
        raise ValueError(f"level must be in (0, 1), got {level}")
    z2 = float(sps.norm.ppf(0.5 + level / 2.0)) ** 2
    centre = (successes + z2 / 2.0) / (n + z2)
    half = math.sqrt(z2) / (n + z2) * math.sqrt(successes * (n - successes) / n + z2 / 4.0)
    lo = 0.0 if successes == 0 else max(0.0, centre - half)
    hi = 1.0 if successes == n else min(1.0, centre + half)
    return lo, hi


def ci_below(a: Sequence[float], b: Sequence[float]) -> bool:
    """Whether interval ``a`` lies wholly below ``b`` (``a_hi < b_lo``): for two independent
    95 % intervals a difference at >= the 95 % level (about 99.4 % for equal errors)."""
    return float(a[1]) < float(b[0])


def _bootstrap_rng(seed: int, world: str, system: str) -> np.random.Generator:
    """The Generator of one system's intervals in one world: independent of the others."""
    names = [zlib.crc32(world.encode()), zlib.crc32(system.encode())]
    return np.random.default_rng([int(seed), *names])


def _per_system(results_by_world: ResultsByWorld, row: Any) -> dict[str, dict[str, Any]]:
    """``{world: {system: row(world, system, trials)}}`` over the systems with trials."""
    return {
        world: {s: row(world, s, results[s]) for s in _ordered_systems(results)}
        for world, results in results_by_world.items()
    }


def table3(results_by_world: ResultsByWorld) -> dict[str, dict[str, dict[str, float]]]:
    """Mean c, tau and f: ``{world: {system: {"c", "tau", "f"}}}`` (the paper's Table 3)."""
    return _per_system(
        results_by_world,
        lambda w, s, trials: {m: float(metric_values(trials, m).mean()) for m in METRICS},
    )


def table5(results_by_world: ResultsByWorld) -> dict[str, dict[str, dict[str, float]]]:
    """Failure percentages ``{world: {system: {"c", "tau", "total"}}}`` (the paper's Table 5);
    a run can breach both caps, so c + tau may exceed total."""

    def row(w: str, s: str, trials: Sequence[Mapping[str, Any]]) -> dict[str, float]:
        return {k: 100.0 * v / len(trials) for k, v in failure_counts(trials).items()}

    return _per_system(results_by_world, row)


def table3_ci(
    results_by_world: ResultsByWorld,
    level: float = CI_LEVEL,
    resamples: int = BOOTSTRAP_RESAMPLES,
    seed: int = BOOTSTRAP_SEED,
) -> dict[str, dict[str, dict[str, list[float]]]]:
    """Bootstrap intervals of every Table 3 mean, c, tau and f from the same resamples:
    ``{world: {system: {metric: [lo, hi]}}}``."""

    def row(w: str, s: str, trials: Sequence[Mapping[str, Any]]) -> dict[str, list[float]]:
        values = np.stack([metric_values(trials, m) for m in METRICS], axis=1)
        lo, hi = bootstrap_mean_ci(values, level, resamples, _bootstrap_rng(seed, w, s))
        return {m: [float(lo[i]), float(hi[i])] for i, m in enumerate(METRICS)}

    return _per_system(results_by_world, row)


def table5_ci(
    results_by_world: ResultsByWorld, level: float = CI_LEVEL
) -> dict[str, dict[str, dict[str, list[float]]]]:
    """Wilson intervals of every Table 5 rate, in %: ``{world: {system: {column: [lo, hi]}}}``."""

    def row(w: str, s: str, trials: Sequence[Mapping[str, Any]]) -> dict[str, list[float]]:
        return {
            k: [100.0 * b for b in proportion_ci(v, len(trials), level)]
            for k, v in failure_counts(trials).items()
        }

    return _per_system(results_by_world, row)


def _compare_metric(a: np.ndarray, b: np.ndarray) -> dict[str, float | int]:
    (t, p), (wt, wp), (u, up) = student_t(a, b), welch_t(a, b), mann_whitney_u(a, b)
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
    """Every Table 4 pair with results under Student's, Welch's and Mann-Whitney tests and
    Cohen's d: ``{world: {"A vs B": {metric: {"n_a", "mean_diff" (A - B), "student_p",
    "level", "welch_t", "mwu_u", "cohens_d", ...}}}}``."""
    return {
        world: {
            f"{a} vs {b}": {
                m: _compare_metric(metric_values(results[a], m), metric_values(results[b], m))
                for m in METRICS
            }
            for a, b in comparison_pairs(world, _ordered_systems(results))
        }
        for world, results in results_by_world.items()
    }


def table4(results_by_world: ResultsByWorld) -> dict[str, dict[str, dict[str, int]]]:
    """Student's t significance levels ``100 (1 - p)``: ``{world: {"A vs B": {metric: int}}}``
    (the paper's Table 4)."""
    return _levels(comparisons(results_by_world))


def _levels(compared: Mapping[str, Mapping[str, Mapping]]) -> dict[str, dict[str, dict[str, int]]]:
    """Table 4's levels of :func:`comparisons`-shaped tests: ``{world: {pair: {metric: int}}}``."""
    return {
        world: {pair: {m: row[m]["level"] for m in METRICS} for pair, row in by_pair.items()}
        for world, by_pair in compared.items()
    }


def record_means(results_by_world: ResultsByWorld, key: str) -> dict[str, dict[str, Any]]:
    """Mean of a record field (``trapped_s``, ``idiotypic_difference_rate``, ...) over the
    trials that have it: ``{world: {system: float | None}}``."""

    def row(w: str, s: str, trials: Sequence[Mapping[str, Any]]) -> float | None:
        values = [float(t[key]) for t in trials if t.get(key) is not None]
        return float(np.mean(values)) if values else None

    return _per_system(results_by_world, row)


def calibration(
    default_by_world: ResultsByWorld,
    hold1_by_world: ResultsByWorld,
    network: Mapping[str, Any],
    system: str = "SIE",
) -> dict[str, Any]:
    """The idiotypic difference rate at the network's k1, k2 under our bouts and with ``hold=1``,
    beside the paper's target ("approximately 20 %" [paper, section 5]): ``{"system", "k1",
    "k2", "paper_percent", "worlds": {world: {"default": rate, "hold=1": rate}}}``."""
    default = record_means(default_by_world, "idiotypic_difference_rate")
    hold1 = record_means(hold1_by_world, "idiotypic_difference_rate")
    return {
        "system": system,
        "k1": float(network["k1"]),
        "k2": float(network["k2"]),
        "paper_percent": protocol.load_paper_tables()["protocol"][
            "idiotypic_difference_rate_target_percent"
        ],
        "worlds": {
            w: {"default": default[w].get(system), "hold=1": hold1.get(w, {}).get(system)}
            for w in default
        },
    }


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
    names = in_order(results_by_world, protocol.WORLDS)
    return [w for w in names if set(needed) <= set(_ordered_systems(results_by_world[w]))]


def _f(results: Results, system: str) -> np.ndarray:
    return metric_values(results[system], "f")


def _interval(iv: Sequence[float]) -> str:
    return f"[{_fmt(float(iv[0]))}, {_fmt(float(iv[1]))}]"


def _ci_view(ok: bool, against: bool, parts: list[str]) -> dict[str, Any]:
    """The CI fields of a verdict: ``ci_supported``, ``ci_contradicted``, ``ci_summary``."""
    return {"ci_supported": ok, "ci_contradicted": against, "ci_summary": "; ".join(parts) + "."}


def _h1(results_by_world: ResultsByWorld, alpha: float, cis: CIs) -> dict[str, Any]:
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
    fails, parts, ci_parts, overlap, reversed_ = [], [], [], [], []
    for w in worlds:
        res = results_by_world[w]
        have = _ordered_systems(res)
        unseeded = [s for s in protocol.UNSEEDED if s in have]
        mean = {s: float(_f(res, s).mean()) for s in have}
        ci = {s: cis[w][s]["f"] for s in have}
        pairs = [("SIE", u) for u in unseeded]
        pairs += [("SRL", u) for u in unseeded if u.startswith("URL") and "SRL" in have]
        overlap += [f"{w}: {a}/{b}" for a, b in pairs if not ci_below(ci[a], ci[b])]
        reversed_ += [f"{w}: {b} below {a}" for a, b in pairs if ci_below(ci[b], ci[a])]
        nearest = min(unseeded, key=lambda u: ci[u][0])
        srl_ci = f", SRL {_interval(ci['SRL'])}" if "SRL" in have else ""
        ci_parts.append(
            f"{w}: SIE f {_interval(ci['SIE'])}{srl_ci} vs nearest unseeded {nearest} "
            f"{_interval(ci[nearest])}"
        )
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
    ci_parts.append("overlapping: " + ", ".join(overlap) if overlap else "all pairs separated")
    ci_parts += ["separated the other way: " + ", ".join(reversed_)] if reversed_ else []
    view = _ci_view(not fails and not overlap, bool(reversed_), ci_parts)
    return _verdict(not fails, rule, parts, fails) | view


def _beats(results_by_world: ResultsByWorld, other: str, alpha: float, cis: CIs) -> dict[str, Any]:
    """SIE has a lower mean f than ``other`` in every world, significantly in a strict majority."""
    rule = (
        f"Rule: SIE's mean f is lower than {other}'s in every world tested, and significantly "
        f"lower (Student's t, p < {alpha:g}) in a strict majority of those worlds."
    )
    worlds = _worlds(results_by_world, ["SIE", other])
    if not worlds:
        return _untestable(f"no world has SIE and {other}")
    fails, parts, n_sig, ci_parts, n_sep, against = [], [], 0, [], 0, False
    for w in worlds:
        a, b = _f(results_by_world[w], "SIE"), _f(results_by_world[w], other)
        ci_a, ci_b = cis[w]["SIE"]["f"], cis[w][other]["f"]
        n_sep += ci_below(ci_a, ci_b)
        against |= ci_below(ci_b, ci_a)
        ci_parts.append(f"{w}: SIE f {_interval(ci_a)} vs {other} {_interval(ci_b)}")
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
    ci_parts.append(f"separated in {n_sep} of {len(worlds)} worlds")
    view = _ci_view(not fails and 2 * n_sep > len(worlds), against, ci_parts)
    return _verdict(not fails, rule, parts, fails) | view


def _h4(results_by_world: ResultsByWorld) -> dict[str, Any]:
    rule = "Rule: SIE (no antibody replacement) has 0 failed trials in every world tested."
    worlds = _worlds(results_by_world, ["SIE"])
    if not worlds:
        return _untestable("no SIE results")
    parts, fails, ci_parts = [], [], []
    for w in worlds:
        trials = results_by_world[w]["SIE"]
        n, failed = len(trials), failure_counts(trials)["total"]
        rate = 100.0 * failed / n
        parts.append(f"{w}: {rate:.0f} % of {n} trials failed")
        if rate > 0:
            fails.append(f"{w}: {rate:.0f} % failures")
        lo, hi = proportion_ci(failed, n)
        ci_parts.append(f"{w}: SIE failure rate [{100 * lo:.2g}, {100 * hi:.2g}] % (Wilson)")
    # A 0 % claim cannot be shown by a sample, only bounded: it holds with its CI when the CI
    # of the rate contains 0 (no failure), and any failure puts the Wilson CI above 0.
    return _verdict(not fails, rule, parts, fails) | _ci_view(not fails, bool(fails), ci_parts)


def _untestable(why: str) -> dict[str, Any]:
    text = f"Not testable: {why}."
    return {"supported": False, "evidence": text, "summary": text} | _ci_view(False, False, [text])


def _verdict(ok: bool, rule: str, parts: list[str], fails: list[str]) -> dict[str, Any]:
    head = "Supported." if ok else "Not supported."
    summary = "; ".join(parts) + "."
    if fails:
        summary += " Violations: " + "; ".join(fails) + "."
    return {"supported": ok, "evidence": f"{head} {rule} {summary}", "summary": summary}


def hypotheses(
    results_by_world: ResultsByWorld, alpha: float = protocol.ALPHA, cis: CIs | None = None
) -> dict[str, dict]:
    """Verdicts on H1-H4 [paper, section 2], judged on f, each also read with the intervals.

    H1: each seeded system's mean f below each unseeded one's of its selection, SIE's
    significantly (Student's t, p < ``alpha``) in every world. H2/H3: SIE's mean f below SRL's /
    HDC's in every world, significantly in a strict majority. H4: SIE never fails. The interval
    reading (``ci_supported``, stricter) also needs every "lower" of the rule to be a separation
    of the f intervals (:func:`ci_below`); ``ci_contradicted``: some pair separates the other way.
    Worlds lacking a rule's systems are skipped; none left is "Not testable".

    Returns:
        ``{"H1": {"supported", "evidence", "summary", "ci_supported", "ci_contradicted",
        "ci_summary"}, ..., "H4": {...}}``.
    """
    cis = table3_ci(results_by_world) if cis is None else cis
    return {
        "H1": _h1(results_by_world, alpha, cis),
        "H2": _beats(results_by_world, "SRL", alpha, cis),
        "H3": _beats(results_by_world, "HDC", alpha, cis),
        "H4": _h4(results_by_world),
    }


def jsonable(obj: Any) -> Any:
    """``obj`` as plain JSON types: NumPy values converted, tuples as lists, inf/NaN as None."""
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


def contender_tables(
    results_by_world: ResultsByWorld,
    contenders_by_world: ResultsByWorld,
    against: Sequence[str] = ("SIE", "HDC"),
) -> dict[str, Any]:
    """Contenders (``contenders_by_world``: ``{world: {label: [record]}}``, systems beyond the
    paper) beside the paper's systems ``against``: Tables 3 and 5 with intervals, and each
    contender's comparisons with those systems as Table 4's (two-tailed Student's t, its level
    100 (1 - p), with Welch's, Mann-Whitney's and Cohen's d beside it):
    ``{"against", "table3", "table3_ci", "table5", "table5_ci", "table4": {world: {"X vs SIE":
    {metric: level}}}, "tests": {world: {"X vs SIE": {metric: {...}}}}}``."""
    merged = {
        world: {s: results_by_world[world][s] for s in against if s in results_by_world[world]}
        | dict(extra)
        for world, extra in contenders_by_world.items()
    }
    tests = {
        world: {
            f"{name} vs {other}": {
                m: _compare_metric(metric_values(mine, m), metric_values(merged[world][other], m))
                for m in METRICS
            }
            for name, mine in extra.items()
            for other in against
            if other in merged[world]
        }
        for world, extra in contenders_by_world.items()
    }
    return jsonable(
        {
            "against": list(against),
            "table3": table3(merged),
            "table3_ci": table3_ci(merged),
            "table5": table5(merged),
            "table5_ci": table5_ci(merged),
            "table4": _levels(tests),
            "tests": tests,
        }
    )


def build_tables(
    results_by_world: ResultsByWorld, alpha: float = protocol.ALPHA, cis: CIs | None = None
) -> dict[str, Any]:
    """Every table of the report as JSON (``cis``: :func:`table3_ci`, computed when None)."""
    if not isinstance(results_by_world, Mapping) or not all(
        isinstance(r, Mapping) for r in results_by_world.values()
    ):
        raise ValueError("results_by_world must be a dict world -> {label: [trial records]}")
    cis = table3_ci(results_by_world) if cis is None else cis
    return jsonable(
        {
            "table3": table3(results_by_world),
            "table3_ci": cis,
            "table4": table4(results_by_world),
            "table5": table5(results_by_world),
            "table5_ci": table5_ci(results_by_world),
            "ci": _CI_SETTINGS,
            **{k: record_means(results_by_world, k) for k in _MEANS},
            "hypotheses": hypotheses(results_by_world, alpha, cis),
        }
    )
