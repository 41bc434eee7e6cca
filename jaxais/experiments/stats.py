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

Confidence intervals (:func:`table3_ci`, :func:`table5_ci`). Every Table 3 mean has a 95 %
percentile bootstrap interval: the trials of a system are resampled with replacement
:data:`BOOTSTRAP_RESAMPLES` (2000) times, the mean of each resample is taken, and the interval
runs from the 2.5th to the 97.5th percentile of those means (linear interpolation, as
``np.quantile`` and ``scipy.stats.bootstrap(method="percentile")`` do). c, tau and f of one
system share the same resamples of its trials. The draws come from a NumPy Generator seeded with
``(seed, crc32(world), crc32(system))``, so an interval depends on the seed and on that
system's trials only, never on which other systems or worlds are present, and every caller
(tables, hypotheses, claims) gets the same interval. A system with one trial, or with the same
value in every trial, gets the point interval ``[x, x]``. A failure rate (Table 5) has a 95 %
Wilson score interval (:func:`proportion_ci`), which stays informative at 0 of n failures
(upper bound about 3.8 / (n + 3.8)), where a bootstrap would collapse onto ``[0, 0]``.
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Iterable, Mapping, Sequence
from typing import Any, Literal, TypedDict

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
    "TrialRecord",
    "baseline_tables",
    "bootstrap_mean_ci",
    "build_tables",
    "ci_below",
    "ci_settings",
    "cohens_d",
    "comparison_pairs",
    "comparisons",
    "hypotheses",
    "idiotypic_difference_rates",
    "failure_causes",
    "jsonable",
    "mann_whitney_u",
    "metric_values",
    "proportion_ci",
    "significance_level",
    "student_t",
    "table3",
    "table3_ci",
    "table4",
    "table5",
    "table5_ci",
    "trapped_times",
    "locked_times",
    "record_means",
    "calibration",
    "welch_t",
]

METRICS: tuple[str, ...] = ("c", "tau", "f")
"""Table 3 / Table 4 metric keys."""
FAILURE_COLUMNS: tuple[str, ...] = ("c", "tau", "total")
"""Table 5 keys: failures by collision cap, by time cap, overall."""

_RECORD_KEY = {"tau": "tau", "f": "fitness"}

CI_LEVEL = 0.95
"""Confidence level of the report's intervals."""
BOOTSTRAP_RESAMPLES = 2000
"""Bootstrap resamples B per interval. Efron & Tibshirani (1993, ch. 19) ask for B >= 1000 for
percentile intervals; at 2000 the Monte Carlo error of a 2.5 % endpoint is a few per cent of the
interval's width."""
BOOTSTRAP_SEED = 0
"""Seed of the bootstrap draws (with the world and system names, see the module docstring)."""


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
CIs = Mapping[str, Mapping[str, Mapping[str, Sequence[float]]]]
"""Intervals as :func:`table3_ci` gives them: ``{world: {system: {metric: [lo, hi]}}}``."""


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


# --------------------------------------------------------------------------- intervals


def bootstrap_mean_ci(
    values: Sequence[float] | np.ndarray,
    level: float = CI_LEVEL,
    resamples: int = BOOTSTRAP_RESAMPLES,
    rng: np.random.Generator | int | None = BOOTSTRAP_SEED,
) -> tuple[np.ndarray, np.ndarray]:
    """Percentile bootstrap confidence interval of the mean.

    The rows of ``values`` are resampled with replacement ``resamples`` times in one draw,
    ``rng.integers(0, n, (resamples, n))`` (the draw ``scipy.stats.bootstrap`` makes), the mean of
    each resample is taken, and the interval is the ``(1 - level) / 2`` and ``(1 + level) / 2``
    quantiles of those means (``np.quantile``'s linear interpolation).

    Args:
        values: ``[n]`` observations, or ``[n, k]``: k statistics of n trials resampled together
            (the same rows in every column).
        level: confidence level in (0, 1).
        resamples: number of resamples, at least 1.
        rng: a NumPy Generator, or a seed for ``np.random.default_rng``.

    Returns:
        ``(lo, hi)``, float64 arrays of shape ``[]`` or ``[k]``; ``lo == hi == x`` when n = 1 or
        every observation is x.

    Raises:
        ValueError: no observations, a level outside (0, 1) or fewer than one resample.
    """
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
    lo, hi = np.quantile(means, [tail, 1.0 - tail], axis=0)
    # Every resample's mean lies in [min, max]; clipping only removes rounding (a constant
    # sample's summed means can miss x by an ulp), so zero variance gives exactly [x, x].
    lo = np.clip(lo, columns.min(axis=0), columns.max(axis=0))
    hi = np.clip(hi, columns.min(axis=0), columns.max(axis=0))
    if x.ndim == 1:
        return lo[0], hi[0]
    return lo, hi


def proportion_ci(successes: int, n: int, level: float = CI_LEVEL) -> tuple[float, float]:
    """Wilson score interval of a proportion ``successes / n`` (e.g. a failure rate).

    ``(k + z^2/2) / (n + z^2) +- z / (n + z^2) sqrt(k (n - k) / n + z^2 / 4)`` with z the
    normal quantile of ``(1 + level) / 2``: inside [0, 1], ``[0, z^2 / (n + z^2)]`` at k = 0 and
    ``[n / (n + z^2), 1]`` at k = n.

    Raises:
        ValueError: n < 1, k outside [0, n] or a level outside (0, 1).
    """
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
    """Whether interval ``a = (lo, hi)`` lies wholly below interval ``b``: ``a_hi < b_lo``.

    For two independent estimates with standard errors s_a and s_b, non-overlapping 95 %
    intervals mean ``|difference| > 1.96 (s_a + s_b) >= 1.96 sqrt(s_a^2 + s_b^2)``: a
    difference at the 95 % level whatever the standard errors, and at about the 99.4 % level
    (z = 1.96 sqrt(2) = 2.77) when they are equal. It is a conservative reading of "a is lower
    than b"; overlapping intervals do not show that the means are equal.
    """
    return float(a[1]) < float(b[0])


def _bootstrap_rng(seed: int, world: str, system: str) -> np.random.Generator:
    """The Generator of one system's intervals in one world (see the module docstring)."""
    names = [zlib.crc32(world.encode()), zlib.crc32(system.encode())]
    return np.random.default_rng([int(seed), *names])


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


def _failure_counts(trials: Sequence[Mapping[str, Any]]) -> dict[str, int]:
    causes = [failure_causes(t) for t in trials]
    failed = [bool(t.get("failed")) or bool(b) for t, b in zip(trials, causes, strict=True)]
    return {
        "c": sum("collisions" in b for b in causes),
        "tau": sum("time" in b for b in causes),
        "total": sum(failed),
    }


def _failure_row(trials: Sequence[Mapping[str, Any]]) -> dict[str, float]:
    n = len(trials)
    return {k: 100.0 * v / n for k, v in _failure_counts(trials).items()}


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


def table3_ci(
    results_by_world: ResultsByWorld,
    level: float = CI_LEVEL,
    resamples: int = BOOTSTRAP_RESAMPLES,
    seed: int = BOOTSTRAP_SEED,
) -> dict[str, dict[str, dict[str, list[float]]]]:
    """Percentile bootstrap intervals of every Table 3 mean (:func:`bootstrap_mean_ci`).

    c, tau and f of a system share its resamples; the draws of a system depend on ``seed``,
    its world's and its own name only (the module docstring), so the result is deterministic.

    Returns:
        ``{world: {system: {"c": [lo, hi], "tau": [lo, hi], "f": [lo, hi]}}}``, the systems of
        :func:`table3`.
    """
    out: dict[str, dict[str, dict[str, list[float]]]] = {}
    for world, results in results_by_world.items():
        out[world] = {}
        for s in _ordered_systems(results):
            values = np.stack([metric_values(results[s], m) for m in METRICS], axis=1)
            lo, hi = bootstrap_mean_ci(values, level, resamples, _bootstrap_rng(seed, world, s))
            out[world][s] = {m: [float(lo[i]), float(hi[i])] for i, m in enumerate(METRICS)}
    return out


def table5_ci(
    results_by_world: ResultsByWorld, level: float = CI_LEVEL
) -> dict[str, dict[str, dict[str, list[float]]]]:
    """Wilson score intervals (:func:`proportion_ci`) of every Table 5 failure rate, in %.

    Returns:
        ``{world: {system: {"c": [lo, hi], "tau": [lo, hi], "total": [lo, hi]}}}`` in [0, 100].
    """
    out: dict[str, dict[str, dict[str, list[float]]]] = {}
    for world, results in results_by_world.items():
        out[world] = {}
        for s in _ordered_systems(results):
            n = len(results[s])
            counts = _failure_counts(results[s])
            out[world][s] = {
                k: [100.0 * v for v in proportion_ci(counts[k], n, level)] for k in FAILURE_COLUMNS
            }
    return out


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


def record_means(results_by_world: ResultsByWorld, key: str) -> dict[str, dict[str, Any]]:
    """Mean of a per-trial record field (e.g. ``trapped_s``) per world and system.

    Returns:
        ``{world: {system: float | None}}``; ``None`` when no trial of the system records it.
    """
    out: dict[str, dict[str, Any]] = {}
    for world, results in results_by_world.items():
        row: dict[str, Any] = {}
        for s in _ordered_systems(results):
            values = [float(t[key]) for t in results[s] if t.get(key) is not None]
            row[s] = float(np.mean(values)) if values else None
        out[world] = row
    return out


def trapped_times(results_by_world: ResultsByWorld) -> dict[str, dict[str, float | None]]:
    """Mean simulated time spent trapped (``trapped_s``, seconds) per world and system."""
    return record_means(results_by_world, "trapped_s")


def locked_times(results_by_world: ResultsByWorld) -> dict[str, dict[str, float | None]]:
    """Mean simulated time spent locked (``locked_s``, seconds: trapped while the same antibody
    kept being selected for each antigen, :class:`jaxais.loop.EpisodeConfig`) per world and
    system."""
    return record_means(results_by_world, "locked_s")


def calibration(
    default_by_world: ResultsByWorld,
    hold1_by_world: ResultsByWorld,
    network: Mapping[str, Any],
    system: str = "SIE",
) -> dict[str, Any]:
    """The idiotypic difference rate at the network's k1, k2, beside the paper's 20 %.

    Section 5: k1 and k2 "are chosen in order to yield a mean idiotypic difference rate of
    approximately 20 %" (the target is read from the packaged paper tables,
    :func:`protocol.load_paper_tables`). Ours is reported under our bout reading and under
    per-iteration selection (``hold=1``).

    Args:
        default_by_world: ``{world: {label: [trial record]}}`` under the default readings.
        hold1_by_world: the same system's trials with ``hold=1``, under its plain label.
        network: the network constants (``k1`` and ``k2`` are shown).

    Returns:
        ``{"system", "k1", "k2", "paper_percent": 20, "worlds": {world: {"default": rate,
        "hold=1": rate}}}`` (rates as fractions, ``None`` where no trial has one).
    """
    default = idiotypic_difference_rates(default_by_world)
    hold1 = idiotypic_difference_rates(hold1_by_world)
    return {
        "system": system,
        "k1": float(network["k1"]),
        "k2": float(network["k2"]),
        "paper_percent": protocol.load_paper_tables()["protocol"][
            "idiotypic_difference_rate_target_percent"
        ],
        "worlds": {
            w: {
                "default": default[w].get(system),
                "hold=1": hold1.get(w, {}).get(system),
            }
            for w in default
        },
    }


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
        row = _failure_row(trials)
        n = len(trials)
        parts.append(f"{w}: {row['total']:.0f} % of {n} trials failed")
        if row["total"] > 0:
            fails.append(f"{w}: {row['total']:.0f} % failures")
        lo, hi = proportion_ci(_failure_counts(trials)["total"], n)
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

    Each verdict also has a reading with the 95 % intervals (``ci_supported``), stricter than
    ``supported``: it holds when the hypothesis is supported and every "lower" and "significantly
    lower" in its rule is also a separation of the f intervals (:func:`table3_ci`,
    :func:`ci_below`): for H1 every pair of the rule (SIE/unseeded, SRL/URL-*); for H2 and H3
    a strict majority of the worlds. H4's 0 % can only be bounded: its CI reading is the rule
    itself (with no failure the Wilson interval of the rate contains 0; after one it does not).
    ``ci_contradicted`` says whether some pair of the rule is separated the other way (H4: some
    failure).

    Args:
        results_by_world: the trials.
        alpha: significance threshold of the t-tests.
        cis: :func:`table3_ci` of ``results_by_world`` (computed here when ``None``).

    Returns:
        ``{"H1": {"supported": bool, "evidence": str, "summary": str, "ci_supported": bool,
        "ci_contradicted": bool, "ci_summary": str}, ..., "H4": {...}}``; the evidence states the
        verdict, the rule, the per-world numbers and any violations; the summary only the numbers
        and violations (it starts "Not testable" when untestable); the CI summary the intervals.
    """
    cis = table3_ci(results_by_world) if cis is None else cis
    return {
        "H1": _h1(results_by_world, alpha, cis),
        "H2": _beats(results_by_world, "SRL", alpha, cis),
        "H3": _beats(results_by_world, "HDC", alpha, cis),
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


def baseline_tables(
    results_by_world: ResultsByWorld,
    baseline_by_world: ResultsByWorld,
    against: Sequence[str] = ("SIE", "HDC"),
    alpha: float = protocol.ALPHA,
) -> dict[str, Any]:
    """Systems beyond the paper (e.g. the neural baseline) beside some of the paper's.

    Args:
        results_by_world: the paper's systems' trials.
        baseline_by_world: ``{world: {system: [TrialRecord]}}`` of the other systems, run under
            the same protocol, seed and worlds.
        against: the paper's systems to set them beside (those a world has).

    Returns:
        ``{"against": [...], "table3": ..., "table3_ci": ..., "table5": ..., "table5_ci": ...,
        "tests": {world: {"NN vs SIE": {"welch_t", "welch_p", "mann_whitney_u",
        "mann_whitney_p", "significant"}}}}``: the tables as :func:`table3` etc. give them for
        the systems of both, and two-sided tests of f between each baseline and each of
        ``against`` at level ``alpha``.
    """
    merged = {
        world: {s: results_by_world[world][s] for s in against if s in results_by_world[world]}
        | dict(extra)
        for world, extra in baseline_by_world.items()
    }
    tests: dict[str, dict[str, dict[str, Any]]] = {}
    for world, extra in baseline_by_world.items():
        tests[world] = {}
        for name, mine in extra.items():
            for other in against:
                if other not in merged[world]:
                    continue
                a, b = metric_values(mine, "f"), metric_values(merged[world][other], "f")
                t, p = welch_t(a, b)
                u, p_u = mann_whitney_u(a, b)
                tests[world][f"{name} vs {other}"] = {
                    "welch_t": t,
                    "welch_p": p,
                    "mann_whitney_u": u,
                    "mann_whitney_p": p_u,
                    "significant": bool(p < alpha),
                }
    return jsonable(
        {
            "against": list(against),
            "table3": table3(merged),
            "table3_ci": table3_ci(merged),
            "table5": table5(merged),
            "table5_ci": table5_ci(merged),
            "tests": tests,
        }
    )


def ci_settings() -> dict[str, Any]:
    """How the tables' intervals were made (``tables.json``'s ``"ci"``)."""
    return {
        "level": CI_LEVEL,
        "table3": "percentile bootstrap of the mean; a system's trials resampled with "
        "replacement, c, tau and f together",
        "resamples": BOOTSTRAP_RESAMPLES,
        "seed": BOOTSTRAP_SEED,
        "table5": "Wilson score interval of the proportion, in %",
    }


def build_tables(
    results_by_world: ResultsByWorld, alpha: float = protocol.ALPHA, cis: CIs | None = None
) -> dict[str, Any]:
    """All of the report's tables, JSON-serialisable.

    Args:
        results_by_world: the trials.
        alpha: significance threshold of the t-tests.
        cis: :func:`table3_ci` of ``results_by_world`` (computed here when ``None``).

    Returns:
        ``{"table3": table3(...), "table3_ci": table3_ci(...), "table4": table4(...),
        "table5": table5(...), "table5_ci": table5_ci(...), "ci": ci_settings(),
        "idiotypic_difference_rate": idiotypic_difference_rates(...),
        "trapped_s": trapped_times(...), "locked_s": locked_times(...),
        "hypotheses": hypotheses(..., alpha)}``.
    """
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
            "ci": ci_settings(),
            "idiotypic_difference_rate": idiotypic_difference_rates(results_by_world),
            "trapped_s": trapped_times(results_by_world),
            "locked_s": locked_times(results_by_world),
            "hypotheses": hypotheses(results_by_world, alpha, cis),
        }
    )
