"""GA checkpoints (orbax): exact round trip, exact resume, refusals and corrupt checkpoints.

Uses the same tiny GA config as ``test_ga.py`` (shared compiled programs).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import jax
import numpy as np
import pytest
from test_ga import TINY, maze, tiny_run

from jaxais import ga
from jaxais.checkpointing import (
    RUN_JSON,
    CheckpointError,
    GACheckpointer,
    abstract_tree,
    state_from_tree,
    state_to_tree,
)

# After a failed restore, orbax's abandoned reads post to a closed asyncio loop; a late report can
# reach pytest's unraisable hook, which turns it into a warning about nothing of ours.
pytestmark = pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning")

INFO = {"world": "ga_maze", "seed": 0, "config": TINY.to_dict()}


def assert_same_state(a: ga.GAState, b: ga.GAState) -> None:
    """Every array bit for bit, the PRNG key included."""
    ta, tb = state_to_tree(a), state_to_tree(b)
    assert ta.keys() == tb.keys()
    for name in ta:
        assert ta[name].dtype == tb[name].dtype, name
        np.testing.assert_array_equal(ta[name], tb[name], err_msg=name)


def one_line(err: BaseException) -> str:
    text = str(err)
    assert "\n" not in text and text
    return text


@pytest.fixture
def saved(tmp_path: Path) -> Path:
    """A checkpoint directory holding generations 1 and 2 of the tiny run."""
    states = []
    ga.run(jax.random.key(0), TINY, maze(), callback=lambda s, e: states.append(s))
    with GACheckpointer(tmp_path / "ck", INFO, resume=False) as ck:
        for s in states:
            ck.save(s, TINY, {"generation": int(s.generation)})
    return tmp_path / "ck"


@pytest.mark.slow
def test_tree_round_trip_is_exact():
    state = tiny_run()
    tree = state_to_tree(state)
    assert tree["key"].dtype == np.uint32
    abstract = abstract_tree(TINY)
    assert {k: (v.shape, v.dtype) for k, v in abstract.items()} == {
        k: (v.shape, v.dtype) for k, v in tree.items()
    }
    back = state_from_tree(tree, TINY, str(jax.random.key_impl(state.key)))
    assert jax.dtypes.issubdtype(back.key.dtype, jax.dtypes.prng_key)
    assert_same_state(state, back)


def test_save_restore_is_exact_and_keeps_two(saved: Path):
    with GACheckpointer(saved, INFO, resume=True) as ck:
        assert ck.latest_generation() == 2
        state, extra = ck.restore(TINY)
        first, extra1 = ck.restore(TINY, generation=1)
    assert extra == {"generation": 2} and extra1 == {"generation": 1}
    assert_same_state(state, tiny_run())
    assert int(first.generation) == 1
    assert json.loads((saved / RUN_JSON).read_text())["seed"] == 0


def test_resume_equals_uninterrupted(tmp_path: Path):
    three = ga.GAConfig(**{**TINY.to_dict(), "generations": 3})
    straight = ga.run(jax.random.key(0), three, maze())
    with GACheckpointer(tmp_path / "ck", INFO, resume=False) as ck:
        ga.run(jax.random.key(0), TINY, maze(), callback=lambda s, e: ck.save(s, TINY))
    with GACheckpointer(tmp_path / "ck", INFO, resume=True) as ck:
        state, _ = ck.restore(three)
        assert int(state.generation) == 2
        resumed = ga.run(state, three, maze(), callback=lambda s, e: ck.save(s, three))
        assert ck.latest_generation() == 3
    assert_same_state(resumed, straight)
    for a, b in zip(
        jax.tree.leaves(ga.best_sets(resumed)), jax.tree.leaves(ga.best_sets(straight)), strict=True
    ):
        np.testing.assert_array_equal(a, b)


def test_missing_checkpoint(tmp_path: Path):
    with pytest.raises(CheckpointError) as info:
        GACheckpointer(tmp_path / "nothing", INFO, resume=True)
    assert "no complete checkpoint" in one_line(info.value)
    (tmp_path / "empty").mkdir()
    with pytest.raises(CheckpointError):
        GACheckpointer(tmp_path / "empty", INFO, resume=True)


def test_refuses_different_arguments_and_overwriting(saved: Path):
    other = {**INFO, "config": {**INFO["config"], "mutation": 0.1}}
    with pytest.raises(CheckpointError) as info:
        GACheckpointer(saved, other, resume=True)
    assert "different arguments" in one_line(info.value) and "mutation" in str(info.value)
    with pytest.raises(CheckpointError) as info:
        GACheckpointer(saved, INFO, resume=False)
    assert "--resume" in one_line(info.value)
    (saved / RUN_JSON).write_text("{not json")
    with pytest.raises(CheckpointError) as info:
        GACheckpointer(saved, INFO, resume=True)
    assert "corrupt" in one_line(info.value)


def _data_files(step_dir: Path) -> list[Path]:
    return [p for p in step_dir.rglob("*") if p.is_file() and p.parent.name == "d"]


@pytest.mark.parametrize("damage", ["truncate", "delete", "meta", "manifest"])
def test_corrupt_checkpoint_is_one_line_error(saved: Path, damage: str):
    step = saved / "2"
    if damage == "truncate":
        for f in _data_files(step):
            with open(f, "r+b") as fh:
                fh.truncate(os.path.getsize(f) // 2)
    elif damage == "delete":
        for f in _data_files(step):
            f.unlink()
    elif damage == "meta":
        (step / "meta" / "metadata").write_text("{bad json")
    else:
        for f in step.rglob("manifest.ocdbt"):
            f.unlink()
    with GACheckpointer(saved, INFO, resume=True) as ck:
        with pytest.raises(CheckpointError) as info:
            ck.restore(TINY)
        # The previous complete checkpoint is still readable.
        state, _ = ck.restore(TINY, generation=1)
    msg = one_line(info.value)
    assert "corrupt checkpoint" in msg and str(step) in msg
    assert int(state.generation) == 1


def test_wrong_shapes_are_a_corrupt_checkpoint(saved: Path):
    bigger = ga.GAConfig(**{**TINY.to_dict(), "robots": 5})
    with GACheckpointer(saved, INFO, resume=True) as ck, pytest.raises(CheckpointError) as info:
        ck.restore(bigger)
    one_line(info.value)


def test_unfinished_save_leaves_the_last_complete_checkpoint(saved: Path):
    # What an interrupted orbax save leaves: a temporary directory that is never renamed.
    tmp = saved / "3.orbax-checkpoint-tmp-1234567"
    (tmp / "state").mkdir(parents=True)
    (tmp / "state" / "partial").write_bytes(b"\0" * 10)
    with GACheckpointer(saved, INFO, resume=True) as ck:
        assert ck.latest_generation() == 2
        state, _ = ck.restore(TINY)
    assert int(state.generation) == 2
    assert not tmp.exists()  # tidied up when the run resumes


@pytest.mark.parametrize(
    ("failure", "reason"),
    [
        (
            ValueError("RESOURCE_EXHAUSTED: Error writing ... [os_error_code='28']\nmore"),
            "No space left on device",
        ),
        (OSError(28, "No space left on device"), "No space left on device"),
        (RuntimeError("disk on fire\nand more"), "disk on fire"),
    ],
)
def test_a_failed_write_is_one_line_naming_the_directory(tmp_path, monkeypatch, failure, reason):
    """A full disk during a save (or during the background save a later call waits for) is one
    CheckpointError line naming the directory, not orbax's report."""
    state = tiny_run(0, 1)
    with GACheckpointer(tmp_path / "ck", INFO, resume=False) as ck:

        def fail(*args, **kwargs):
            raise failure

        monkeypatch.setattr(ck._manager, "save", fail)
        with pytest.raises(CheckpointError) as info:
            ck.save(state, TINY)
        monkeypatch.setattr(ck._manager, "wait_until_finished", fail)
        with pytest.raises(CheckpointError):
            ck.close()
        monkeypatch.undo()
    msg = str(info.value)
    assert "\n" not in msg and msg.startswith(str(tmp_path / "ck"))
    assert f"({reason})" in msg and "--resume" in msg
