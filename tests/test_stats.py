"""Tests of jaxais.experiments.stats: hand-worked statistics, table assembly and H1-H4 verdicts."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from _records import trial
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats as sps

from jaxais.experiments import protocol, stats

A = [1.0, 2.0, 3.0]
B = [4.0, 5.0, 6.0, 7.0]


# --------------------------------------------------------------------------- references (no scipy)


def t_density(x: np.ndarray, df: float) -> np.ndarray:
    """Student's t density, written out with math.lgamma."""
    log_c = math.lgamma((df + 1) / 2) - math.lgamma(df / 2) - 0.5 * math.log(df * math.pi)
    return np.exp(log_c) * (1 + x**2 / df) ** (-(df + 1) / 2)


def two_tailed_p_by_integration(t: float, df: float) -> float:
    """p = 1 - 2 * integral_0^|t| density (trapezoid rule on 200 001 points)."""
    x = np.linspace(0.0, abs(t), 200_001)
    return 1.0 - 2.0 * float(np.trapezoid(t_density(x, df), x))


def two_tailed_p_df5(t: float) -> float:
    """Closed form for 5 degrees of freedom (Abramowitz & Stegun 26.7.3):
    P(|T| < t) = (2/pi) (theta + sin(theta) cos(theta) (1 + (2/3) cos^2(theta))),
    theta = atan(t / sqrt(5))."""
    th = math.atan(abs(t) / math.sqrt(5))
    a = 2 / math.pi * (th + math.sin(th) * math.cos(th) * (1 + 2 / 3 * math.cos(th) ** 2))
    return 1.0 - a


def trials_with_f(f_mean: float, n: int = 8, spread: float = 4.0) -> list[dict]:
    """n trials with c = 0 whose f values are f_mean + spread * (-1.75, ..., 1.75)."""
    offsets = np.linspace(-1.75, 1.75, n) * spread
    return [trial(2 * (f_mean + o)) for o in offsets]


# --------------------------------------------------------------------------- systems and pairs


def test_comparison_pairs_follow_table4_and_filter_per_world():
    assert len(protocol.COMPARISONS) == 12
    assert protocol.COMPARISONS[0] == ("SIE", "SRL")
    assert protocol.COMPARISONS[-1] == ("UIE-R2", "URL-R2")
    assert stats.comparison_pairs("world1") == protocol.COMPARISONS
    real = stats.comparison_pairs("real")
    assert real == (
        ("SIE", "SRL"),
        ("SIE", "HDC"),
        ("SIE", "UIE-R1"),
        ("SIE", "URL-R1"),
        ("SRL", "UIE-R1"),
        ("SRL", "URL-R1"),
        ("UIE-R1", "URL-R1"),
    )
    assert stats.comparison_pairs("world1", ["SIE", "HDC", "SRL"]) == (
        ("SIE", "SRL"),
        ("SIE", "HDC"),
    )


# --------------------------------------------------------------------------- hand-worked tests


def test_student_t_by_hand():
    # mean_a = 2, mean_b = 5.5; s_a^2 = 1, s_b^2 = (2.25 + .25 + .25 + 2.25)/3 = 5/3.
    # pooled s^2 = (2*1 + 3*5/3) / 5 = 7/5; se^2 = 7/5 * (1/3 + 1/4) = 49/60.
    # t = -3.5 / sqrt(49/60) = -sqrt(15) on 5 df.
    t, p = stats.student_t(A, B)
    assert t == pytest.approx(-math.sqrt(15), rel=1e-12)
    assert p == pytest.approx(two_tailed_p_df5(math.sqrt(15)), rel=1e-9)
    assert p == pytest.approx(two_tailed_p_by_integration(math.sqrt(15), 5), abs=1e-8)
    # Table value: t_{0.995, 5} = 4.032 and t_{0.99, 5} = 3.365, so 0.01 < p < 0.02.
    assert 0.01 < p < 0.02
    assert stats.significance_level(p) == 99  # 100 (1 - 0.01172) = 98.8


def test_welch_t_by_hand():
    # se^2 = 1/3 + (5/3)/4 = 3/4, t = -3.5 / sqrt(3/4) = -7/sqrt(3).
    # df = (3/4)^2 / ((1/3)^2/2 + (5/12)^2/3) = (9/16) / (49/432) = 243/49.
    t, p = stats.welch_t(A, B)
    assert t == pytest.approx(-7 / math.sqrt(3), rel=1e-12)
    assert p == pytest.approx(two_tailed_p_by_integration(7 / math.sqrt(3), 243 / 49), abs=1e-8)


def test_cohens_d_by_hand():
    # d = (2 - 5.5) / sqrt(7/5)
    assert stats.cohens_d(A, B) == pytest.approx(-3.5 / math.sqrt(1.4), rel=1e-12)
    assert stats.cohens_d(B, A) == pytest.approx(3.5 / math.sqrt(1.4), rel=1e-12)


def test_mann_whitney_u_by_hand():
    # No a_i exceeds any b_j: U = 0. Exact two-sided p = 2 * P(U <= 0) = 2 / C(7, 3) = 2/35.
    u, p = stats.mann_whitney_u(A, B)
    assert u == 0.0
    assert p == pytest.approx(2 / 35, rel=1e-12)
    # With ties: a = [1, 3, 5], b = [2, 3, 4]. Pairs a > b: 1 -> 0; 3 -> 1 (2) + 0.5 (tie 3);
    # 5 -> 3. U = 4.5 = n_a n_b / 2, so the test sees no shift.
    u, p = stats.mann_whitney_u([1, 3, 5], [2, 3, 4])
    assert u == 4.5
    assert p == pytest.approx(1.0)
    u_ab, _ = stats.mann_whitney_u(B, A)
    assert u_ab == 12.0  # U_a + U_b = n_a n_b


def test_significance_level_rounds_half_up():
    assert stats.significance_level(0.0) == 100
    assert stats.significance_level(0.005) == 100  # 99.5
    assert stats.significance_level(0.0149) == 99
    assert stats.significance_level(0.51) == 49
    assert stats.significance_level(1.0) == 0


def test_degenerate_cases():
    # Zero variance, equal means: no difference.
    assert stats.student_t([2, 2, 2], [2, 2]) == (0.0, 1.0)
    assert stats.welch_t([2, 2, 2], [2, 2]) == (0.0, 1.0)
    assert stats.cohens_d([2, 2, 2], [2, 2]) == 0.0
    assert stats.mann_whitney_u([2, 2, 2], [2, 2]) == (3.0, 1.0)
    # Zero variance, different means: certain difference, infinite statistic with A's sign.
    assert stats.student_t([1, 1, 1], [3, 3]) == (-math.inf, 0.0)
    assert stats.welch_t([3, 3], [1, 1, 1]) == (math.inf, 0.0)
    assert stats.cohens_d([1, 1, 1], [3, 3]) == -math.inf
    # Too few observations to estimate a variance: no evidence.
    assert stats.student_t([1], [2]) == (0.0, 1.0)
    assert stats.welch_t([1], [2, 3, 4]) == (0.0, 1.0)
    assert stats.cohens_d([1], [2]) == 0.0
    # One group of one with the other varying is fine for Student's (pooled) test.
    t, p = stats.student_t([1], [2, 3, 4])
    assert math.isfinite(t) and 0 < p < 1
    # One group constant, the other not: Welch works (df = n_b - 1).
    t, p = stats.welch_t([0, 0, 0], [1, 2, 3])
    assert t == pytest.approx(-2 / math.sqrt(1 / 3))
    with pytest.raises(ValueError):
        stats.student_t([], [1, 2])


@settings(max_examples=40, deadline=None)
@given(
    st.lists(st.floats(-1e3, 1e3), min_size=2, max_size=12),
    st.lists(st.floats(-1e3, 1e3), min_size=2, max_size=12),
)
def test_t_tests_match_scipy_reference(a, b):
    if np.var(a) < 1e-6 or np.var(b) < 1e-6:
        return  # scipy returns NaN here; our documented degenerate rules differ on purpose
    t, p = stats.student_t(a, b)
    ref = sps.ttest_ind(a, b)
    np.testing.assert_allclose([t, p], [ref.statistic, ref.pvalue], rtol=1e-7, atol=1e-12)
    t, p = stats.welch_t(a, b)
    ref = sps.ttest_ind(a, b, equal_var=False)
    np.testing.assert_allclose([t, p], [ref.statistic, ref.pvalue], rtol=1e-7, atol=1e-12)


# --------------------------------------------------------------------------- tables


def small_results() -> dict:
    return {
        "world1": {
            # c 2, tau 150, f (8*2 + 150)/2 = 83, trapped (1 + 3)/2 = 2.
            "SIE": [trial(100, 1, trapped=1.0), trial(200, 3, trapped=3.0)],
            # Failed by time; by collisions; by both (2500 collisions and the 4000 s cap); none.
            # Capped c: 2, 100, 100, 2 -> 51; tau 8900/4 = 2225; f (8*51 + 2225)/2 = 1316.5.
            "HDC": [
                trial(4000, 2),
                trial(300, 150, trapped=20.0),
                trial(4000, 2500, trapped=3000.0),
                trial(600, 2),
            ],
            "UIE-R2": [trial(50, 0, rate=0.1), trial(70, 0, rate=0.3), trial(60, 0)],
        },
        "real": {
            "SIE": [trial(10, 0, rate=0.2), trial(20, 0, rate=0.4)],
            "UIE-R2": [trial(10, 0), trial(20, 0)],  # not a real-world system: no comparison
        },
    }


def test_table3_means_use_the_capped_collision_count():
    t3 = stats.table3(small_results())
    assert t3["world1"]["SIE"] == {"c": 2.0, "tau": 150.0, "f": 83.0}
    # Raw c would average (2 + 150 + 2500 + 2)/4 = 663.5; Table 3 caps each count at 100.
    assert t3["world1"]["HDC"] == {"c": 51.0, "tau": 2225.0, "f": 1316.5}
    np.testing.assert_array_equal(
        stats.metric_values(small_results()["world1"]["HDC"], "c"), [2, 100, 100, 2]
    )
    # Paper's system order, whatever the input order.
    assert list(t3["world1"]) == ["SIE", "UIE-R2", "HDC"]


def test_table5_failure_rates_overlap():
    t5 = stats.table5(small_results())
    # One run by time, one by collisions, one by both, one finished: c 2/4, tau 2/4, either 3/4.
    assert t5["world1"]["HDC"] == {"c": 50.0, "tau": 50.0, "total": 75.0}
    assert t5["world1"]["SIE"] == {"c": 0.0, "tau": 0.0, "total": 0.0}


def test_failure_counts():
    runs = [trial(4000, 2500), trial(100, 100), trial(100, 101), trial(4000, 3)]
    # c = 100 is not > 100; a run can breach both caps.
    assert stats.failure_counts(runs) == {"c": 2, "tau": 2, "total": 3}


def test_trapped_times():
    trapped = stats.record_means(small_results(), "trapped_s")
    assert trapped["world1"]["SIE"] == 2.0
    assert trapped["world1"]["HDC"] == pytest.approx((0 + 20 + 3000 + 0) / 4)
    assert list(trapped["world1"]) == ["SIE", "UIE-R2", "HDC"]


def test_table4_and_comparisons_filtered_per_world():
    res = small_results()
    comps = stats.comparisons(res)
    assert list(comps["world1"]) == ["SIE vs HDC", "SIE vs UIE-R2"]
    assert comps["real"] == {}  # R2 is not a real-world system
    row = comps["world1"]["SIE vs HDC"]["tau"]
    assert row["mean_diff"] == pytest.approx(150 - 2225)
    assert set(row) == {
        "n_a",
        "n_b",
        "mean_a",
        "mean_b",
        "mean_diff",
        "student_t",
        "student_p",
        "level",
        "welch_t",
        "welch_p",
        "mwu_u",
        "mwu_p",
        "cohens_d",
    }
    t, p = stats.student_t([100, 200], [4000, 300, 4000, 600])
    assert row["student_t"] == t and row["level"] == stats.significance_level(p)
    t4 = stats.table4(res)
    assert t4["world1"]["SIE vs HDC"]["tau"] == row["level"]
    assert set(t4["world1"]["SIE vs HDC"]) == {"c", "tau", "f"}
    # The c test runs on the capped counts too.
    c_row = comps["world1"]["SIE vs HDC"]["c"]
    assert c_row["mean_b"] == 51.0
    assert c_row["student_t"] == stats.student_t([1, 3], [2, 100, 100, 2])[0]


def test_idiotypic_difference_rates():
    rates = stats.record_means(small_results(), "idiotypic_difference_rate")
    assert rates["world1"]["UIE-R2"] == pytest.approx(0.2)  # None ignored
    assert rates["world1"]["HDC"] is None
    assert rates["real"]["SIE"] == pytest.approx(0.3)


def test_build_tables_is_plain_json():
    res = small_results()
    res["world2"] = {"SIE": [trial(10), trial(10)], "SRL": [trial(30), trial(30)]}  # t = -inf
    tables = stats.build_tables(res)
    assert set(tables) == {
        "table3",
        "table3_ci",
        "table4",
        "table5",
        "table5_ci",
        "ci",
        "idiotypic_difference_rate",
        "trapped_s",
        "locked_s",
        "hypotheses",
    }
    assert tables["trapped_s"]["world1"]["SIE"] == 2.0
    assert tables["locked_s"]["world1"]["SIE"] == 0.0
    assert tables["table4"]["world2"]["SIE vs SRL"]["tau"] == 100
    assert tables["table3_ci"] == stats.table3_ci(res)
    assert tables["table3_ci"]["world2"]["SIE"]["tau"] == [10.0, 10.0]
    assert tables["table5_ci"]["world1"]["SIE"]["total"][0] == 0.0
    assert tables["ci"]["resamples"] == stats.BOOTSTRAP_RESAMPLES == 2000
    assert tables["ci"]["level"] == 0.95
    assert set(tables["hypotheses"]["H1"]) >= {"ci_supported", "ci_contradicted", "ci_summary"}
    json.loads(json.dumps(tables, allow_nan=False))


# --------------------------------------------------------------------------- intervals


def percentile_ci_by_loop(x: list[float], seed: int, resamples: int, level: float = 0.95):
    """The percentile bootstrap written out: one index drawn at a time from the same Generator
    stream, plain-Python means, and the quantiles by sorting and linear interpolation
    (Hyndman & Fan type 7)."""
    rng = np.random.default_rng(seed)
    n = len(x)
    means = sorted(
        math.fsum(x[int(rng.integers(0, n))] for _ in range(n)) / n for _ in range(resamples)
    )

    def quantile(q: float) -> float:
        h = (resamples - 1) * q
        i = math.floor(h)
        j = min(i + 1, resamples - 1)
        return means[i] + (h - i) * (means[j] - means[i])

    tail = (1 - level) / 2
    return quantile(tail), quantile(1 - tail)


@pytest.mark.parametrize("n", [2, 7, 30])
def test_bootstrap_ci_matches_a_loop_of_resamples(n):
    x = list(np.random.default_rng(n).exponential(300.0, n))
    lo, hi = stats.bootstrap_mean_ci(x, resamples=500, rng=np.random.default_rng(11))
    ref = percentile_ci_by_loop(x, seed=11, resamples=500)
    np.testing.assert_allclose([lo, hi], ref, rtol=1e-12)
    assert lo <= np.mean(x) <= hi


def test_bootstrap_ci_matches_scipy_percentile():
    x = np.random.default_rng(5).lognormal(5.0, 1.0, 40)
    got = stats.bootstrap_mean_ci(x, level=0.9, resamples=2000, rng=np.random.default_rng(7))
    res = sps.bootstrap(
        (x,),
        np.mean,
        method="percentile",
        confidence_level=0.9,
        n_resamples=2000,
        rng=np.random.default_rng(7),
    )
    ci = res.confidence_interval
    np.testing.assert_allclose(got, (ci.low, ci.high), rtol=1e-9)


def test_bootstrap_ci_columns_share_their_resamples():
    x = np.random.default_rng(2).normal(size=(25, 3))
    lo, hi = stats.bootstrap_mean_ci(x, rng=4)
    assert lo.shape == hi.shape == (3,)
    for k in range(3):
        np.testing.assert_allclose(
            (lo[k], hi[k]), stats.bootstrap_mean_ci(x[:, k], rng=4), rtol=1e-12
        )
    # A linear function of the columns: its resampled means are that function of theirs.
    f_lo, f_hi = stats.bootstrap_mean_ci(np.stack([x[:, 0], 3 * x[:, 0] + 1], axis=1), rng=4)
    np.testing.assert_allclose(f_lo[1], 3 * f_lo[0] + 1, rtol=1e-12)
    np.testing.assert_allclose(f_hi[1], 3 * f_hi[0] + 1, rtol=1e-12)


def test_bootstrap_ci_is_deterministic_for_a_seed():
    x = np.arange(20.0) ** 2
    assert stats.bootstrap_mean_ci(x, rng=3) == stats.bootstrap_mean_ci(x, rng=3)
    assert stats.bootstrap_mean_ci(x, rng=3) != stats.bootstrap_mean_ci(x, rng=4)


def test_bootstrap_ci_degenerate_samples():
    assert stats.bootstrap_mean_ci([42.5]) == (42.5, 42.5)  # one trial
    assert stats.bootstrap_mean_ci([0.1] * 7) == (0.1, 0.1)  # zero variance: exactly x
    lo, hi = stats.bootstrap_mean_ci([[4000.0, 3.0], [4000.0, 5.0]], resamples=1)
    assert lo[0] == hi[0] == 4000.0 and np.isfinite([lo, hi]).all()
    for bad in ([], np.zeros((0, 3))):
        with pytest.raises(ValueError):
            stats.bootstrap_mean_ci(bad)
    with pytest.raises(ValueError):
        stats.bootstrap_mean_ci([1.0, 2.0], level=1.0)
    with pytest.raises(ValueError):
        stats.bootstrap_mean_ci([1.0, 2.0], resamples=0)


def test_bootstrap_ci_covers_the_mean_about_95_percent_of_the_time():
    # 400 normal samples of 30 (true mean 0): the percentile interval's coverage is a little
    # under 95 % at this size; 1.96 binomial SE is about 1.1 %.
    rng = np.random.default_rng(0)
    covered = 0
    for _ in range(400):
        lo, hi = stats.bootstrap_mean_ci(rng.normal(size=30), resamples=1000, rng=rng)
        covered += lo <= 0.0 <= hi
    assert 0.89 <= covered / 400 <= 0.98


def test_proportion_ci_wilson():
    z = sps.norm.ppf(0.975)
    # 0 of n: [0, z^2 / (n + z^2)]; n of n mirrors it.
    assert stats.proportion_ci(0, 30) == (0.0, pytest.approx(z**2 / (30 + z**2)))
    assert stats.proportion_ci(30, 30) == (pytest.approx(30 / (30 + z**2)), 1.0)
    assert stats.proportion_ci(0, 1000)[1] == pytest.approx(0.00383, abs=1e-5)
    # The Wilson bounds are the two roots of |k/n - p| = z sqrt(p (1 - p) / n).
    for k, n in ((1, 30), (7, 20), (300, 1000)):
        lo, hi = stats.proportion_ci(k, n)
        assert 0 < lo < k / n < hi < 1
        for p in (lo, hi):
            assert abs(k / n - p) == pytest.approx(z * math.sqrt(p * (1 - p) / n), rel=1e-9)
    for k, n in ((-1, 5), (6, 5), (0, 0)):
        with pytest.raises(ValueError):
            stats.proportion_ci(k, n)


def test_ci_below_is_strict_separation():
    assert stats.ci_below([1, 2], [2.5, 3])
    assert not stats.ci_below([1, 2], [2, 3])  # touching intervals overlap
    assert not stats.ci_below([2.5, 3], [1, 2])


def test_table3_ci():
    res = small_results()
    ci = stats.table3_ci(res)
    assert list(ci["world1"]) == ["SIE", "UIE-R2", "HDC"]
    assert set(ci["world1"]["SIE"]) == set(stats.METRICS)
    # Capped c: HDC's counts 2, 100, 100, 2 resample to means within [2, 100].
    lo, hi = ci["world1"]["HDC"]["c"]
    assert 2.0 <= lo < 51.0 < hi <= 100.0
    # A system's intervals depend on its own trials, the seed and the names only.
    alone = stats.table3_ci({"world1": {"HDC": res["world1"]["HDC"]}})
    assert alone["world1"]["HDC"] == ci["world1"]["HDC"]
    assert stats.table3_ci(res) == ci
    assert stats.table3_ci(res, seed=1)["world1"]["HDC"] != ci["world1"]["HDC"]
    # One trial, and zero variance, give point intervals.
    single = stats.table3_ci({"real": {"SIE": [trial(77.0, 3)]}})["real"]["SIE"]
    assert single == {"c": [3.0, 3.0], "tau": [77.0, 77.0], "f": [50.5, 50.5]}


def test_table5_ci():
    ci = stats.table5_ci(small_results())
    hdc = ci["world1"]["HDC"]
    for key, k in (("c", 2), ("tau", 2), ("total", 3)):
        assert hdc[key] == pytest.approx([100 * b for b in stats.proportion_ci(k, 4)])
    assert ci["world1"]["SIE"]["total"][0] == 0.0


def test_contender_tables_set_contenders_beside_the_papers_systems():
    res = small_results()
    nn = [trial(100.0), trial(4000.0, 3), trial(300.0, 120)]  # f 50, 2012, 550
    got = stats.contender_tables(res, {"world1": {"NN": nn}}, against=("SIE", "HDC", "SRL"))
    assert list(got["table3"]["world1"]) == ["SIE", "HDC", "NN"]  # SRL has no trials here
    assert got["table3"]["world1"]["NN"] == pytest.approx({"c": 103 / 3, "tau": 4400 / 3,
                                                           "f": 2612 / 3})  # fmt: skip
    # The paper's systems' rows and intervals are their Table 3's, untouched by the contender.
    assert got["table3_ci"]["world1"]["SIE"] == stats.table3_ci(res)["world1"]["SIE"]
    assert got["table5"]["world1"]["NN"] == pytest.approx({"c": 100 / 3, "tau": 100 / 3,
                                                           "total": 200 / 3})  # fmt: skip
    assert got["table5_ci"]["world1"]["NN"]["total"] == pytest.approx(
        [100 * b for b in stats.proportion_ci(2, 3)]
    )
    # Table 4's test: two-tailed Student's t, its level 100 (1 - p); Welch's beside it.
    test = got["tests"]["world1"]["NN vs HDC"]
    f_hdc = [r["fitness"] for r in res["world1"]["HDC"]]
    ref = sps.ttest_ind([50.0, 2012.0, 550.0], f_hdc, equal_var=True)
    welch = sps.ttest_ind([50.0, 2012.0, 550.0], f_hdc, equal_var=False)
    assert test["f"]["student_t"] == pytest.approx(ref.statistic)
    assert test["f"]["student_p"] == pytest.approx(ref.pvalue)
    assert test["f"]["welch_p"] == pytest.approx(welch.pvalue)
    assert got["table4"]["world1"]["NN vs HDC"]["f"] == round(100 * (1 - ref.pvalue))
    assert set(got["tests"]["world1"]) == {"NN vs SIE", "NN vs HDC"}
    assert set(got["table4"]["world1"]["NN vs SIE"]) == set(stats.METRICS)
    json.dumps(got, allow_nan=False)


# --------------------------------------------------------------------------- hypotheses


def paper_like(overrides: dict | None = None, worlds=protocol.WORLDS) -> dict:
    """All systems in all worlds, SIE best by far, with f means overridable per world/system."""
    base = {"SIE": 100, "SRL": 200, "HDC": 300, "UIE-R1": 400, "UIE-R2": 420}
    base |= {"URL-R1": 500, "URL-R2": 520}
    out = {}
    for w in worlds:
        means = base | (overrides or {}).get(w, {})
        out[w] = {s: trials_with_f(means[s]) for s in protocol.systems_for_world(w)}
    return out


def test_all_hypotheses_supported_on_clear_results():
    h = stats.hypotheses(paper_like())
    assert {k: v["supported"] for k, v in h.items()} == dict.fromkeys(
        ("H1", "H2", "H3", "H4"), True
    )
    assert h["H1"]["evidence"].startswith("Supported.")
    assert "world1: SIE f 100" in h["H1"]["evidence"]
    assert "significant in 3 of 3 worlds" in h["H2"]["evidence"]


def test_h1_fails_when_srl_is_worse_than_url():
    h = stats.hypotheses(paper_like({"world2": {"SRL": 510}}))
    assert not h["H1"]["supported"]
    assert "world2: SRL f 510 >= URL-R1 500" in h["H1"]["evidence"]
    # SRL vs UIE (different selection) is not part of the rule.
    assert stats.hypotheses(paper_like({"real": {"SRL": 450}}))["H1"]["supported"]


def test_h1_fails_when_sie_not_significantly_better():
    res = paper_like()
    res["world1"]["UIE-R1"] = trials_with_f(103)  # above SIE's 100, but not significantly
    h = stats.hypotheses(res)
    assert not h["H1"]["supported"]
    assert "SIE vs UIE-R1 lower but not significantly" in h["H1"]["evidence"]


def test_h1_evidence_says_when_sie_is_worse():
    res = paper_like()
    res["world1"]["URL-R1"] = trials_with_f(50)  # well below SIE's 100
    h = stats.hypotheses(res)
    assert not h["H1"]["supported"]
    assert "world1: SIE f 100 >= URL-R1 50" in h["H1"]["evidence"]


def test_h2_needs_a_strict_majority_of_significant_worlds():
    # Like the paper: significant in world1 and real, lower but not significant in world2.
    res = paper_like()
    res["world2"]["SRL"] = trials_with_f(103)
    h = stats.hypotheses(res)
    assert h["H2"]["supported"]
    assert "significant in 2 of 3 worlds" in h["H2"]["evidence"]
    res["real"]["SRL"] = trials_with_f(103)
    h = stats.hypotheses(res)
    assert not h["H2"]["supported"]
    assert "significant in only 1 of 3 worlds" in h["H2"]["evidence"]


def test_h2_and_h3_fail_when_sie_is_worse_somewhere():
    h = stats.hypotheses(paper_like({"real": {"SRL": 90, "HDC": 50}}))
    assert not h["H2"]["supported"] and not h["H3"]["supported"]
    assert "real: SIE f 100 >= SRL 90" in h["H2"]["evidence"]
    assert "real: SIE f 100 >= HDC 50" in h["H3"]["evidence"]


def test_h4_needs_zero_sie_failures():
    res = paper_like()
    assert stats.hypotheses(res)["H4"]["supported"]
    res["real"]["SIE"][0] = trial(4000, 0)
    h = stats.hypotheses(res)
    assert not h["H4"]["supported"]
    assert "real: 12 % failures" in h["H4"]["evidence"]


def test_missing_worlds_are_skipped_and_untestable_is_not_supported():
    h = stats.hypotheses(paper_like(worlds=("world2",)))
    assert all(v["supported"] for v in h.values())
    assert "world1" not in h["H2"]["evidence"]
    assert "significant in 1 of 1 worlds" in h["H2"]["evidence"]
    h = stats.hypotheses({"world1": {"HDC": trials_with_f(100)}})
    assert not any(v["supported"] for v in h.values())
    assert all(v["evidence"].startswith("Not testable") for v in h.values())
    assert all(v["summary"] == v["evidence"] for v in h.values())


def test_hypothesis_summary_has_the_numbers_without_the_rule():
    h = stats.hypotheses(paper_like())["H2"]
    assert h["evidence"].endswith(h["summary"])
    assert "Rule:" not in h["summary"] and "world1: SIE f 100 vs SRL 200" in h["summary"]


def test_hypotheses_with_intervals():
    h = stats.hypotheses(paper_like())
    assert all(v["ci_supported"] and not v["ci_contradicted"] for v in h.values())
    assert "all pairs separated" in h["H1"]["ci_summary"]
    assert "separated in 3 of 3 worlds" in h["H2"]["ci_summary"]
    assert "SIE failure rate [0, 32] % (Wilson)" in h["H4"]["ci_summary"]  # 0 of 8
    # SRL reversed, clearly, in the real world: H2 fails and the intervals contradict it.
    h = stats.hypotheses(paper_like({"real": {"SRL": 50}}))
    assert not h["H2"]["ci_supported"] and h["H2"]["ci_contradicted"]
    # Given intervals (as from table3_ci): H2 supported on the means and t-tests, but SIE's and
    # SRL's intervals overlap in world2 and the real world: held, not with intervals.
    res = paper_like()
    cis = stats.table3_ci(res)
    for w in ("world2", "real"):
        cis[w]["SRL"]["f"] = [cis[w]["SIE"]["f"][1], 250.0]  # touching counts as overlapping
    h = stats.hypotheses(res, cis=cis)
    assert h["H2"]["supported"] and "significant in 3 of 3 worlds" in h["H2"]["summary"]
    assert not h["H2"]["ci_supported"] and not h["H2"]["ci_contradicted"]
    assert "separated in 1 of 3 worlds" in h["H2"]["ci_summary"]
    assert h["H1"]["ci_supported"]  # SRL is not in H1's SIE pairs, and still below URL-*
    cis["world1"]["URL-R2"]["f"] = [0.0, 1.0]  # below SIE's: separated the other way
    h1 = stats.hypotheses(res, cis=cis)["H1"]
    assert h1["supported"] and not h1["ci_supported"] and h1["ci_contradicted"]
    assert "separated the other way: world1: URL-R2 below SIE" in h1["ci_summary"]
    # A failure contradicts H4 with its interval too.
    res = paper_like()
    res["real"]["SIE"][0] = trial(4000, 0)
    h4 = stats.hypotheses(res)["H4"]
    assert not h4["ci_supported"] and h4["ci_contradicted"]
    untestable = stats.hypotheses({"world1": {"HDC": trials_with_f(100)}})["H1"]
    assert not untestable["ci_supported"] and untestable["ci_summary"].startswith("Not testable")


def test_locked_times_and_the_calibration_point():
    rec = lambda locked, rate: {"locked_s": locked, "idiotypic_difference_rate": rate}
    default = {
        "world1": {"SIE": [rec(0.0, 0.3), rec(10.0, 0.4)], "SRL": [rec(30.0, None)] * 2},
        "real": {"SIE": [rec(2.0, 0.5), rec(4.0, 0.6)]},
    }
    hold1 = {"world1": {"SIE": [rec(0.0, 0.1), rec(0.0, 0.2)]}, "real": {"SIE": [rec(0, 0.25)]}}
    locked = stats.record_means(default, "locked_s")
    assert locked == {"world1": {"SIE": 5.0, "SRL": 30.0}, "real": {"SIE": 3.0}}
    cal = stats.calibration(default, hold1, {"k1": 0.85, "k2": 1.1})
    assert (cal["system"], cal["k1"], cal["k2"], cal["paper_percent"]) == ("SIE", 0.85, 1.1, 20)
    assert cal["worlds"]["world1"] == {
        "default": pytest.approx(0.35),
        "hold=1": pytest.approx(0.15),
    }
    assert cal["worlds"]["real"] == {"default": pytest.approx(0.55), "hold=1": 0.25}
