"""``records_frame`` checks what it is given before reading it, and names the record that holds a
NaN or an infinity (a results file holds finite numbers, ``null`` where a value does not apply)."""

from __future__ import annotations

import json

import pytest

from jaxais.experiments.records import FORMATS, records_frame
from jaxais.io import ArgumentTypeError


def trial(tau: float = 12.5, rate: float | None = 0.25) -> dict:
    return {"tau": tau, "collisions": 1, "failed_by": [], "idiotypic_difference_rate": rate}


def trials_doc(**changes) -> dict:
    doc = {"format": FORMATS["trials"], "system": "SIE", "label": "SIE", "world": "world1",
           "random_set": None, "seed": 0, "trials": [trial(), trial(rate=None)]}  # fmt: skip
    return {k: v for k, v in (doc | changes).items() if v != "drop"}


def point(tau: float = 20.0) -> dict:
    return {"values": {"k1": 0.5}, "n": 2, "tau": {"mean": tau, "ci": [tau - 1, tau + 1]},
            "idiotypic_difference_rate": None, "trials": [trial(), trial()]}  # fmt: skip


def test_records_frame_refuses_wrong_inputs_in_one_line_naming_them(tmp_path):
    doc, fields = "the document: ", " field (docs/formats.md)"
    cases = [
        (123, "records_frame's source must be a results file's path or its JSON document (a "
              "dict), got int 123"),
        (trials_doc(trials="drop"), f"{doc}no 'trials'{fields}"),
        (trials_doc(label="drop"), f"{doc}no 'label'{fields}"),
        (trials_doc(trials="x"), f"{doc}'trials' must be a list of objects, got str 'x'"),
        (trials_doc(trials=[1, 2]), f"{doc}trials[0] must be an object, got int 1"),
        ({"format": FORMATS["sweep"], "points": {}},
         f"{doc}'points' must be a list of objects, got dict"),
        ({"format": FORMATS["sweep"], "points": [{"n": 2}]}, f"{doc}point 0: no 'values'{fields}"),
        ({"format": FORMATS["reality_gap"], "points": [{"scale": 1.0, "systems": []}]},
         f"{doc}point 0: 'systems' must be an object, got list"),
    ]  # fmt: skip
    for source, message in cases:
        with pytest.raises(ValueError) as err:
            records_frame(source)
        assert str(err.value) == message
    with pytest.raises(ArgumentTypeError, match="records_frame's runs must be a bool, got str"):
        records_frame(trials_doc(), runs="yes")
    path = tmp_path / "t.json"
    path.write_text(json.dumps(trials_doc(trials="x")))
    with pytest.raises(ValueError, match=rf"^{path}: 'trials' must be a list of objects"):
        records_frame(path)
    assert records_frame(trials_doc())["idiotypic_difference_rate"].isna().tolist() == [
        False,
        True,  # null by design: no idiotypic selection in that trial
    ]


def test_records_frame_names_the_record_holding_a_non_finite_value(tmp_path):
    path = tmp_path / "t.json"
    doc = trials_doc(trials=[trial(), trial(), trial(tau=float("nan"))])
    path.write_text(json.dumps(doc))  # Python writes NaN; a results file never holds one
    with pytest.raises(ValueError) as err:
        records_frame(path)
    assert str(err.value) == (
        f"{path}: trial 2 (label 'SIE') holds tau = nan: a results file holds finite numbers "
        "(null where a value does not apply); it was damaged or edited"
    )
    sweep = {"format": FORMATS["sweep"], "points": [point(), point(tau=float("inf"))]}
    with pytest.raises(ValueError, match=r"^the document: point 1 holds tau = inf: "):
        records_frame(sweep)
    sweep["points"] = [point(), point()]
    sweep["points"][1]["trials"][1]["tau"] = float("-inf")
    assert len(records_frame(sweep)) == 2  # the points' means are finite
    with pytest.raises(ValueError, match=r"^the document: point 1's trial 1 holds tau = -inf: "):
        records_frame(sweep, runs=True)
    gap_point = {"scale": 2.0, "systems": {"SRL": point(), "SIE": point(tau=float("nan"))}}
    gap = {"format": FORMATS["reality_gap"], "points": [gap_point]}
    with pytest.raises(ValueError, match=r"^the document: point 0's label 'SIE' holds tau = nan"):
        records_frame(gap)
