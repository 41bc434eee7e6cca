"""Tests of jaxais.experiments.claims: the paper's 32 claims judged on hand-built results."""

from __future__ import annotations

import json

import numpy as np
import pytest
from _records import trial

from jaxais.experiments import claims, protocol, stats

# Per system: (capped-or-raw c, mean tau). SIE best on every metric, SRL < URL-R1, UIE-R1 < URL-R1.
CLEAR = {
    "SIE": (1, 500),
    "SRL": (4, 1000),
    "UIE-R1": (20, 1500),
    "URL-R1": (40, 2000),
    "UIE-R2": (25, 1600),
    "URL-R2": (45, 2100),
    "HDC": (2, 1300),
}


def system(c: int, tau: float, n: int = 8, spread: float = 40.0) -> list[dict]:
    """n trials with c collisions each and tau = tau + spread * (-1.75, ..., 1.75)."""
    return [trial(tau + o, c) for o in np.linspace(-1.75, 1.75, n) * spread]


def results(overrides: dict | None = None, worlds=protocol.WORLDS) -> dict:
    out = {}
    for w in worlds:
        spec = CLEAR | (overrides or {}).get(w, {})
        out[w] = {s: system(*spec[s]) for s in protocol.systems_for_world(w)}
    return out


def by_id(ledger: list[dict]) -> dict[str, dict]:
    return {c["id"]: c for c in ledger}


def test_all_32_claims_hold_on_clear_results():
    ledger = claims.claims(results())
    assert len(ledger) == 32 and len(by_id(ledger)) == 32
    assert [c["world"] for c in ledger].count("world1") == 10
    assert [c["world"] for c in ledger].count("world2") == 10
    assert [c["world"] for c in ledger].count("real") == 8
    assert [c["id"] for c in ledger[-4:]] == ["H1", "H2", "H3", "H4"]
    assert [c["id"] for c in ledger[:10]] == [
        "world1/SIE-lowest-c",
        "world1/SIE-lowest-tau",
        "world1/SIE-lowest-f",
        "world1/SIE-no-failures",
        "world1/SIE-f-sig-below/UIE-R1",
        "world1/SIE-f-sig-below/URL-R1",
        "world1/SIE-f-sig-below/UIE-R2",
        "world1/SIE-f-sig-below/URL-R2",
        "world1/SRL-f-below/URL-R1",
        "world1/UIE-R1-f-below/URL-R1",
    ]
    assert all(c["held"] is True for c in ledger), [c for c in ledger if not c["held"]]
    assert claims.summary(ledger) == {"reproduced": 32, "total": 32, "evaluated": 32}
    assert set(ledger[0]) == {
        "id",
        "world",
        "text",
        "held",
        "evidence",
        "ci_held",
        "ci_verdict",
        "ci_evidence",
    }
    # Clear results are clear with their intervals too: every claim holds with them.
    assert all(c["ci_held"] is True for c in ledger), [c for c in ledger if not c["ci_held"]]
    assert {c["ci_verdict"] for c in ledger} == {
        claims.HELD_SEPARATED,
        claims.HELD_ZERO_IN_CI,
    }
    assert claims.ci_summary(ledger) == {
        "reproduced": 32,
        "reproduced_with_ci": 32,
        "contradicted_with_ci": 0,
        "evaluated": 32,
        "level": 0.95,
    }
    assert all(c["text"] and c["evidence"] for c in ledger)
    # The real world has only the R1 unseeded systems.
    assert "real/SIE-f-sig-below/UIE-R2" not in by_id(ledger)


def test_evidence_numbers():
    res = results()
    got = by_id(claims.claims(res))
    # SIE f = (8 + 500) / 2 = 254, HDC (16 + 1300) / 2 = 658, SIE c 1 vs HDC 2 (lowest other).
    assert got["world1/SIE-lowest-c"]["evidence"] == "SIE 1.00; lowest other: HDC 2.00."
    assert got["world1/SIE-lowest-f"]["evidence"] == "SIE 254.0; lowest other: SRL 516.0."
    _, p = stats.student_t(
        stats.metric_values(res["real"]["SIE"], "f"),
        stats.metric_values(res["real"]["URL-R1"], "f"),
    )
    assert got["real/SIE-f-sig-below/URL-R1"]["evidence"] == (
        f"SIE f 254.0 vs URL-R1 1160.0; p={p:.2g} (level 100)."
    )
    assert got["world2/SRL-f-below/URL-R1"]["evidence"] == "SRL f 516.0 vs URL-R1 1160.0."
    assert got["H2"]["evidence"].startswith("world1: SIE f 254 vs SRL 516")
    assert "Rule:" not in got["H2"]["evidence"]


def test_a_tie_counts_as_lowest_but_not_as_lower():
    # world2: HDC's c equals SIE's (as in the paper's Table 3); world1: URL-R1's f equals SRL's.
    srl_f = (8 * 4 + 1000) / 2
    got = by_id(
        claims.claims(results({"world2": {"HDC": (1, 1300)}, "world1": {"URL-R1": (4, 1000)}}))
    )
    assert got["world2/SIE-lowest-c"]["held"] is True
    assert got["world2/SIE-lowest-c"]["evidence"] == "SIE 1.00; lowest other: HDC 1.00 (a tie)."
    assert got["world1/SRL-f-below/URL-R1"]["held"] is False
    assert got["world1/SRL-f-below/URL-R1"]["evidence"] == f"SRL f {srl_f} vs URL-R1 {srl_f}."


def test_claims_that_fail():
    res = results({"world1": {"HDC": (0, 1300)}, "real": {"UIE-R1": (40, 2100)}})
    res["world2"]["UIE-R1"] = system(1, 510)  # f 259 vs SIE's 254: lower, not significantly
    got = by_id(claims.claims(res))
    assert got["world1/SIE-lowest-c"]["held"] is False
    assert got["world1/SIE-lowest-c"]["evidence"] == "SIE 1.00; lowest other: HDC 0.00."
    assert got["world1/SIE-lowest-f"]["held"] is True  # HDC's f (0 + 1300)/2 = 650 > 254
    sig = got["world2/SIE-f-sig-below/UIE-R1"]
    assert sig["held"] is False and "(level" in sig["evidence"]
    assert got["world2/SIE-lowest-f"]["held"] is True
    assert got["real/UIE-R1-f-below/URL-R1"]["held"] is False  # 1210 vs 1160
    assert got["H1"]["held"] is False  # SIE vs UIE-R1 not significant in world2
    counts = claims.summary(list(got.values()))
    assert counts == {"reproduced": 28, "total": 32, "evaluated": 32}


def test_a_run_failed_by_both_caps():
    res = results()
    res["world1"]["SIE"][0] = trial(4000, 2500)  # more than 100 collisions and no finish
    t5 = stats.table5(res)["world1"]["SIE"]
    assert t5 == {"c": 12.5, "tau": 12.5, "total": 12.5}  # 1 of 8; c + tau > total
    got = by_id(claims.claims(res))
    assert got["world1/SIE-no-failures"]["held"] is False
    assert got["world1/SIE-no-failures"]["evidence"] == (
        "1 of 8 SIE trials failed (12 %; by c: 1, by τ: 1)."
    )
    assert got["world2/SIE-no-failures"]["held"] is True
    assert got["H4"]["held"] is False


def test_a_missing_world_is_not_evaluated():
    ledger = claims.claims(results(worlds=("world1", "world2")))
    got = by_id(ledger)
    real = [c for c in ledger if c["world"] == "real"]
    assert len(real) == 8
    assert all(c["held"] is None and c["evidence"] == "No results for real." for c in real)
    assert got["H1"]["held"] is True  # decided on the worlds that were run
    assert claims.summary(ledger) == {"reproduced": 24, "total": 32, "evaluated": 24}
    assert claims.headline(claims.summary(ledger)) == (
        "**24 of 24 of the paper's claims reproduced**"
    )


def test_missing_systems():
    res = results()
    del res["world1"]["HDC"]
    res["world2"]["SIE"] = []  # no trials counts as missing
    got = by_id(claims.claims(res))
    assert got["world1/SIE-lowest-c"]["held"] is True
    assert got["world1/SIE-lowest-c"]["evidence"].endswith("; no results for HDC.")
    for cid in ("world2/SIE-lowest-tau", "world2/SIE-no-failures", "world2/SIE-f-sig-below/URL-R2"):
        assert got[cid]["held"] is None
        assert got[cid]["evidence"] == "No results for SIE in world2."
    assert got["world2/SRL-f-below/URL-R1"]["held"] is True


def test_nothing_testable():
    ledger = claims.claims({"world1": {"HDC": system(2, 1300)}})
    assert all(c["held"] is None for c in ledger)
    assert by_id(ledger)["H3"]["evidence"].startswith("Not testable")
    assert by_id(ledger)["world1/SIE-lowest-c"]["evidence"] == "No results for SIE in world1."
    assert claims.summary(ledger) == {"reproduced": 0, "total": 32, "evaluated": 0}


def test_sie_alone_cannot_be_lowest():
    got = by_id(claims.claims({"world1": {"SIE": system(1, 500)}}))
    assert got["world1/SIE-lowest-f"]["held"] is None
    assert got["world1/SIE-lowest-f"]["evidence"] == "No other system in world1."
    assert got["world1/SIE-no-failures"]["held"] is True


@pytest.mark.parametrize("alpha", [0.01, 1e-30])
def test_alpha_sets_the_significance_threshold(alpha):
    # SIE vs UIE-R1 in world1: p is tiny (about 1e-17) but not below 1e-30.
    got = by_id(claims.claims(results(), alpha=alpha))
    assert got["world1/SIE-f-sig-below/UIE-R1"]["held"] is (alpha == 0.01)


def test_document_is_plain_json():
    ledger = claims.claims(results(worlds=("world2",)))
    doc = claims.document(ledger)
    assert set(doc) == {"summary", "ci_summary", "claims"}
    assert doc["summary"] == claims.summary(ledger)
    assert doc["ci_summary"] == claims.ci_summary(ledger)
    assert doc["claims"] == ledger
    assert json.loads(json.dumps(doc, allow_nan=False)) == doc


# --------------------------------------------------------------------------- with intervals


def test_interval_readings():
    res = results({"world1": {"HDC": (0, 1300)}, "world2": {"HDC": (1, 1300)}})
    res["world2"]["UIE-R1"] = system(1, 510)  # f 259 vs SIE's 254: lower, not significantly
    res["world1"]["SIE"][0] = trial(4000, 2500)  # one failure, by both caps
    cis = stats.table3_ci(res)
    got = by_id(claims.claims(res, cis=cis))
    # A tie of means (c 1 = 1, both constant): held on the means, the intervals overlap.
    tie = got["world2/SIE-lowest-c"]
    assert (tie["held"], tie["ci_held"], tie["ci_verdict"]) == (True, False, claims.HELD_OVERLAP)
    # UIE-R1 (c 1 here) and HDC tie with SIE; the first in table order is shown.
    assert tie["ci_evidence"] == "SIE [1.00, 1.00]; UIE-R1 [1.00, 1.00]."
    # HDC's c (0) is below SIE's (1) on every resample: contradicted.
    low = got["world1/SIE-lowest-c"]
    assert low["held"] is False and low["ci_verdict"] == claims.NOT_HELD_SEPARATED
    assert low["ci_evidence"].endswith("HDC [0.00, 0.00].")
    # Lower, not significantly; overlapping intervals.
    sig = got["world2/SIE-f-sig-below/UIE-R1"]
    assert (sig["held"], sig["ci_verdict"]) == (False, claims.NOT_HELD_OVERLAP)
    lo, hi = cis["world2"]["UIE-R1"]["f"]
    assert (
        sig["ci_evidence"].startswith("SIE f [")
        and f"UIE-R1 [{lo:.1f}, {hi:.1f}]" in (sig["ci_evidence"])
    )
    # One failure in 8: the Wilson interval of the rate excludes 0.
    fail = got["world1/SIE-no-failures"]
    assert (fail["held"], fail["ci_held"], fail["ci_verdict"]) == (
        False,
        False,
        claims.NOT_HELD_ZERO_OUT,
    )
    wlo, whi = stats.proportion_ci(1, 8)
    assert fail["ci_evidence"] == f"SIE failure rate [{100 * wlo:.2g}, {100 * whi:.2g}] % (Wilson)."
    ok = got["world2/SIE-no-failures"]
    assert (ok["ci_held"], ok["ci_verdict"]) == (True, claims.HELD_ZERO_IN_CI)
    assert ok["ci_evidence"].startswith("SIE failure rate [0, 32] %")
    assert got["H4"]["ci_verdict"] == claims.NOT_HELD_ZERO_OUT
    counts = claims.ci_summary(list(got.values()))
    assert counts["reproduced"] == claims.summary(list(got.values()))["reproduced"]
    assert counts["reproduced_with_ci"] == sum(c["ci_held"] is True for c in got.values())
    assert counts["contradicted_with_ci"] == sum(
        c["ci_verdict"] in (claims.NOT_HELD_SEPARATED, claims.NOT_HELD_ZERO_OUT)
        for c in got.values()
    )
    assert all(c["ci_verdict"] in claims.CI_VERDICTS for c in got.values())


def test_held_but_overlapping_and_the_t_test_disagreeing():
    # Intervals given by hand: SIE's f interval reaches into URL-R1's in world1.
    res = results()
    cis = stats.table3_ci(res)
    cis["world1"]["URL-R1"]["f"] = [cis["world1"]["SIE"]["f"][1] - 1.0, 5000.0]
    got = by_id(claims.claims(res, cis=cis))
    sig = got["world1/SIE-f-sig-below/URL-R1"]
    assert (sig["held"], sig["ci_held"], sig["ci_verdict"]) == (True, False, claims.HELD_OVERLAP)
    assert got["world1/SRL-f-below/URL-R1"]["ci_verdict"] == claims.HELD_OVERLAP
    assert got["H1"]["held"] is True and got["H1"]["ci_verdict"] == claims.HELD_OVERLAP
    # Significance fails (alpha tiny) while the intervals separate as claimed.
    got = by_id(claims.claims(res, alpha=1e-300))
    sig = got["world1/SIE-f-sig-below/URL-R1"]
    assert (sig["held"], sig["ci_held"], sig["ci_verdict"]) == (
        False,
        False,
        claims.NOT_HELD_BY_TEST,
    )


def test_unevaluated_claims_have_no_interval_reading():
    ledger = claims.claims(results(worlds=("world1",)))
    for c in ledger:
        if c["held"] is None:
            assert c["ci_held"] is None and c["ci_verdict"] is None and c["ci_evidence"] == ""
    counts = claims.ci_summary(ledger)
    assert counts["evaluated"] == claims.summary(ledger)["evaluated"]
    assert "of the" in claims.ci_headline(counts) and "95 %" in claims.ci_headline(counts)
