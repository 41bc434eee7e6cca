"""The LTL seed on disk (``jaxais.seed``): exact round trip and one-line errors for bad seeds."""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable
from pathlib import Path

import _stl_fixtures as F
import numpy as np
import pytest
from _python import run_python

from jaxais.seed import (
    ARRAYS_DIR,
    CROSSING,
    SEED_JSON,
    Seed,
    SeedError,
    check_crossing,
    load_seed,
    save_seed,
)

# After a failed restore, orbax's abandoned reads post to a closed asyncio loop; a late report can
# reach pytest's unraisable hook, which turns it into a warning that says nothing about the seed.
pytestmark = pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning")

PROVENANCE = {"command": "test_seed.py", "seed": 7, "version": "0.0-test"}
CROSSING_ENTRY = {
    "starts": 50,
    "rate": [0.9, 0.82, 1.0, 0.96, 0.88],
    "tau_cap": 500.0,
    "world": "ga_maze",
}


def seed_arrays(seed: Seed) -> dict[str, np.ndarray]:
    out = {f"ab_{k}": np.asarray(v) for k, v in vars(seed.antibodies).items()}
    out.update(tau=np.asarray(seed.tau), collisions=np.asarray(seed.collisions), L=seed.L)
    return {k: np.asarray(v) for k, v in out.items()}


def assert_same(a: Seed, b: Seed) -> None:
    xa, xb = seed_arrays(a), seed_arrays(b)
    assert xa.keys() == xb.keys()
    for k in xa:
        assert xa[k].dtype == xb[k].dtype, k
        assert xa[k].shape == xb[k].shape, k
        assert xa[k].tobytes() == xb[k].tobytes(), k  # bit-identical


@pytest.fixture(scope="module")
def pristine(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One good seed directory; each case copies it."""
    return save_seed(tmp_path_factory.mktemp("seeds") / "seed", F.random_seed(1), PROVENANCE)


def test_round_trip_is_bit_identical(tmp_path: Path):
    seed = F.random_seed(2)
    path = save_seed(tmp_path / "out" / "seed", seed, PROVENANCE)
    assert path == (tmp_path / "out" / "seed").absolute()
    assert (path / SEED_JSON).is_file() and (path / ARRAYS_DIR).is_dir()
    loaded, meta = load_seed(path)
    assert_same(seed, loaded)
    assert {k: meta[k] for k in PROVENANCE} == PROVENANCE
    assert len(meta["sets"]) == 5
    assert [s["tau"] for s in meta["sets"]] == [float(t) for t in seed.tau]
    assert [s["collisions"] for s in meta["sets"]] == [int(c) for c in seed.collisions]
    assert meta["sets"][3]["L"] == [float(x) for x in seed.L[3]]


def test_crossing_entry_round_trip(tmp_path: Path):
    seed = F.random_seed(2)
    save_seed(tmp_path / "seed", seed, PROVENANCE, crossing=CROSSING_ENTRY)
    loaded, meta = load_seed(tmp_path / "seed")
    assert_same(seed, loaded)
    assert meta[CROSSING] == CROSSING_ENTRY
    _, plain = load_seed(save_seed(tmp_path / "plain", seed, PROVENANCE))
    assert CROSSING not in plain  # optional


@pytest.mark.parametrize(
    "change, words",
    [
        ({"starts": 0}, "starts"),
        ({"starts": 2.5}, "starts"),
        ({"rate": [0.9] * 4}, "5 fractions"),
        ({"rate": [0.9, 0.82, 1.2, 0.96, 0.88]}, "fraction"),
        ({"rate": [0.9, 0.81, 1.0, 0.96, 0.88]}, "whole number"),
        ({"tau_cap": -1}, "tau_cap"),
        ({"tau_cap": None}, "tau_cap"),
    ],
)
def test_malformed_crossing_entry_is_refused(change, words, pristine: Path, tmp_path: Path):
    entry = {**CROSSING_ENTRY, **change}
    assert words in check_crossing(entry, 5)
    with pytest.raises(ValueError, match=words):
        save_seed(tmp_path / "new", F.random_seed(1), PROVENANCE, crossing=entry)
    path = tmp_path / "seed"
    shutil.copytree(pristine, path)
    _edit_json(lambda d: d.update({CROSSING: entry}))(path)
    with pytest.raises(SeedError) as info:
        load_seed(path)
    msg = str(info.value)
    assert "malformed" in msg and "crossing" in msg and words in msg and "\n" not in msg
    assert check_crossing(CROSSING_ENTRY, 5) is None and "object" in check_crossing([], 5)


def test_shipped_default_seed_loads():
    seed, meta = load_seed()
    assert seed.antibodies.type.shape == (5, 8) and seed.L.shape == (5, 8)
    assert meta["format"] == "jaxais-seed/1"


def test_saving_over_a_seed_replaces_it(tmp_path: Path):
    path = tmp_path / "seed"
    save_seed(path, F.random_seed(3), PROVENANCE)
    save_seed(path, F.random_seed(4), {**PROVENANCE, "seed": 4})
    loaded, meta = load_seed(path)
    assert_same(F.random_seed(4), loaded)
    assert meta["seed"] == 4
    assert sorted(p.name for p in tmp_path.iterdir()) == ["seed"]  # no temporary left behind


def _edit_json(fn: Callable[[dict], None]) -> Callable[[Path], None]:
    def edit(path: Path) -> None:
        doc = json.loads((path / SEED_JSON).read_text())
        fn(doc)
        (path / SEED_JSON).write_text(json.dumps(doc))

    return edit


def _truncate(pattern: str) -> Callable[[Path], None]:
    def edit(path: Path) -> None:
        files = sorted(p for p in (path / ARRAYS_DIR).glob(pattern) if p.is_file())
        assert files, pattern
        for f in files:
            f.write_bytes(f.read_bytes()[:5])

    return edit


def _set_type(doc: dict) -> None:
    ab = doc["sets"][2]["antibodies"][4]
    if ab["type"] == "static turn":
        new = {"type": "reverse turn", "S": 300, "A": 50, "D": "left"}
    else:
        new = {"type": "static turn", "S": 60, "A": 100, "D": "left"}
    doc["sets"][2]["antibodies"][4] = {"antigen": ab["antigen"], **new}


CASES = {
    "missing directory": (lambda p: shutil.rmtree(p), "no such seed directory"),
    "a file, not a directory": (
        lambda p: (shutil.rmtree(p), p.write_text("x")),
        "no such seed directory",
    ),
    "missing arrays/": (lambda p: shutil.rmtree(p / ARRAYS_DIR), "not a seed directory"),
    "missing seed.json": (lambda p: (p / SEED_JSON).unlink(), "not a seed directory"),
    "deleted arrays/_METADATA": (
        lambda p: (p / ARRAYS_DIR / "_METADATA").unlink(),
        "corrupt seed",
    ),
    "truncated arrays/_METADATA": (_truncate("_METADATA"), "corrupt seed (arrays/: "),
    "truncated manifest": (_truncate("manifest.ocdbt"), "corrupt seed"),
    "truncated data file": (_truncate("d/*"), "corrupt seed"),
    "deleted data files": (
        lambda p: [f.unlink() for f in (p / ARRAYS_DIR / "d").iterdir()],
        "corrupt seed",
    ),
    "seed.json not JSON": (
        lambda p: (p / SEED_JSON).write_text("{not json"),
        "corrupt seed (seed.json: ",
    ),
    "seed.json malformed": (
        _edit_json(lambda d: d["sets"][0].update(antibodies=[{"type": "fly"}])),
        "malformed",
    ),
    "seed.json without sets": (_edit_json(lambda d: d.pop("sets")), "malformed"),
    "seed.json with another behaviour type": (_edit_json(_set_type), "disagrees"),
    "seed.json with a set missing": (_edit_json(lambda d: d["sets"].pop()), "disagrees"),
    "an unknown format version": (
        _edit_json(lambda d: d.update(format="jaxais-seed/9")),
        "has format 'jaxais-seed/9', this jaxais reads 'jaxais-seed/1'",
    ),
    "no format": (_edit_json(lambda d: d.pop("format")), "has format None"),
}


@pytest.mark.parametrize("case", list(CASES))
def test_bad_seed_is_a_one_line_seed_error(case: str, pristine: Path, tmp_path: Path):
    damage, words = CASES[case]
    path = tmp_path / "seed"
    shutil.copytree(pristine, path)
    load_seed(path)  # the copy is good
    damage(path)
    with pytest.raises(SeedError) as info:
        load_seed(path)
    msg = str(info.value)
    assert words in msg
    assert "\n" not in msg and msg.startswith(str(path))
    assert "scripts/evolve.py" in msg  # says how to make a new one
    assert isinstance(info.value, ValueError)  # the scripts report ValueErrors in one line


def test_a_corrupt_seed_leaves_nothing_on_stderr(pristine: Path, tmp_path: Path):
    """orbax abandons its other reads when one fails; their late callbacks print nothing (they
    printed a traceback after the scripts' one-line error). Whether a read is still pending when
    orbax gives up is a race, so the seed is read ten times."""
    path = tmp_path / "seed"
    shutil.copytree(pristine, path)
    _truncate("d/*")(path)
    code = (
        "import time\n"
        "from jaxais.seed import SeedError, load_seed\n"
        "for _ in range(10):\n"
        "    try:\n"
        f"        load_seed({str(path)!r})\n"
        "    except SeedError:\n"
        "        print('refused')\n"
        "time.sleep(1)  # the abandoned reads end meanwhile\n"
    )
    out = run_python(code)
    assert out.stdout.split() == ["refused"] * 10, out.stderr[-2000:]
    assert out.stderr == ""


def test_seed_breaking_table_1_or_with_bad_shapes_is_refused(tmp_path: Path):
    seed = F.random_seed(5)
    speed = np.array(seed.antibodies.speed)
    speed[0, 0] = 5000.0
    fast = seed.replace(antibodies=seed.antibodies.replace(speed=speed))
    save_seed(tmp_path / "fast", fast, PROVENANCE)
    with pytest.raises(SeedError, match="Table 1"):
        load_seed(tmp_path / "fast")
    save_seed(tmp_path / "short", seed.replace(L=np.asarray(seed.L)[:, :7]), PROVENANCE)
    with pytest.raises(SeedError, match="inconsistent shapes"):
        load_seed(tmp_path / "short")


@pytest.mark.parametrize(
    ("field", "value", "words"),
    [
        ("tau", -5.0, "task times must be finite and > 0 s"),
        ("tau", 0.0, "task times must be finite and > 0 s"),
        ("tau", np.inf, "task times must be finite and > 0 s"),
        ("collisions", -1, "collision counts must be >= 0"),
        ("L", -0.5, "RL scores L must be finite and >= 0"),
    ],
)
def test_seed_with_impossible_tau_c_or_L_is_refused(field, value, words, tmp_path: Path):
    seed = F.random_seed(5)
    bad = np.array(getattr(seed, field))
    bad.flat[1] = value
    save_seed(tmp_path / "bad", seed.replace(**{field: bad}), PROVENANCE)
    with pytest.raises(SeedError, match=words) as info:
        load_seed(tmp_path / "bad")
    assert "\n" not in str(info.value) and "scripts/evolve.py" in str(info.value)


@pytest.mark.parametrize(
    "edit",
    [
        lambda d: d["sets"][0].update(tau=1.0),
        lambda d: d["sets"][1].update(collisions=99),
        lambda d: d["sets"][2]["L"].__setitem__(0, 77.0),
        lambda d: d["sets"][3]["antibodies"][0].update(
            S=float(d["sets"][3]["antibodies"][0]["S"]) + 1
        ),
    ],
    ids=["tau", "collisions", "L", "S"],
)
def test_seed_json_numbers_disagreeing_with_arrays_are_refused(edit, pristine, tmp_path):
    path = tmp_path / "seed"
    shutil.copytree(pristine, path)
    _edit_json(edit)(path)
    with pytest.raises(SeedError, match="disagrees"):
        load_seed(path)
