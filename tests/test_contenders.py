"""Contenders as given (``jaxais.experiments.contenders``): the forms ``resolve`` takes, the
labels it refuses, what it records; nothing runs (the runs: tests/test_scripts_stl.py)."""

from __future__ import annotations

from pathlib import Path

import pytest

from jaxais.controllers import BRAITENBERG, braitenberg_params
from jaxais.experiments import contenders as C

ROOT = Path(__file__).resolve().parent.parent
SPEC = "examples/braitenberg.py:braitenberg"


def test_every_form_gives_one_contender_with_its_source(monkeypatch):
    monkeypatch.chdir(ROOT)
    pair = (BRAITENBERG, braitenberg_params())
    by_spec, by_object, relabelled = C.resolve({"BV": SPEC, "BR": pair, "X": C.load_spec(SPEC)})
    assert [c.label for c in (by_spec, by_object, relabelled)] == ["BV", "BR", "X"]
    assert by_spec.source["spec"] == SPEC and len(by_spec.source["sha256"]) == 64
    assert by_spec.source["about"].startswith("A Braitenberg-style vehicle")
    assert by_object.source == {"spec": None} and by_object.controller is BRAITENBERG
    # A file loads once: the same controller object (compiled programs are cached by it).
    assert by_spec.controller is relabelled.controller
    (listed,) = C.resolve([f"BV={SPEC}"])
    assert listed.label == "BV" and listed.source["spec"] == f"BV={SPEC}"
    assert C.resolve(None) == [] and C.resolve(SPEC)[0].label == "braitenberg"
    assert C.check_specs(f"BV={SPEC}") == [("BV", f"BV={SPEC}")]


@pytest.mark.parametrize(
    ("given", "message"),
    [
        ({"SIE": SPEC}, "label 'SIE' is the paper's"),
        ({"UIE-R1": SPEC}, "must be an identifier"),
        ({"no label": SPEC}, "must be an identifier"),
        ([SPEC, SPEC], "given twice"),
        ({"BV": (1, 2)}, "NAME must be a (Controller, params) tuple"),
        ({"BV": lambda: 3}, "NAME must be a (Controller, params) tuple"),
        (["nofile.py:x"], "no such file nofile.py"),
        (["examples/braitenberg.py:missing"], "defines no 'missing'"),
        (["examples/braitenberg.py"], "write [LABEL=]FILE.py:NAME"),
        (3, "contenders must be a dict"),
    ],
)
def test_mistakes_are_one_line(given, message, monkeypatch):
    monkeypatch.chdir(ROOT)
    with pytest.raises(ValueError) as info:
        C.resolve(given)
    assert message in str(info.value) and "\n" not in str(info.value)


def test_a_failing_file_is_named_with_its_error(tmp_path):
    bad = tmp_path / "bad.py"
    bad.write_text("raise RuntimeError('half written')\n")
    with pytest.raises(ValueError, match=r"cannot load .*bad\.py: RuntimeError: half written"):
        C.load_spec(f"{bad}:x")
    broken = tmp_path / "broken.py"
    broken.write_text("def make():\n    raise KeyError('k')\n")
    with pytest.raises(ValueError, match="calling it failed: KeyError"):
        C.load_spec(f"{broken}:make")
