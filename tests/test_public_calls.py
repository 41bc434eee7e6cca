"""Every public call checks its arguments' types before their ranges, before any work: a wrong
type is one line naming the argument (a ValueError; an ArgumentTypeError where it is a type), a
size that allocates is bounded by the machine's memory, and nothing is written or compiled.

One table of (call, expected message); each case must fail before JAX compiles anything (a
compile listener counts), so the whole table runs in seconds.
"""

from __future__ import annotations

import contextlib
import functools
import re
from pathlib import Path

import jax
import pytest

from jaxais import envs, load_seed, make_system, make_trials, run_trials
from jaxais import experiments as x
from jaxais.experiments import ablation, protocol
from jaxais.io import ArgumentTypeError, check_names, check_type

OUT = "OUT"  # replaced by a fresh folder's path in each case
GRID = ["k1=0:1:2"]
_COMPILES = frozenset(f"/jax/core/compile/{e}_duration" for e in ("backend_compile",))


def _beside(out: str, name: str) -> str:
    """A file in the case's (empty) folder, beside the output folder it must not create."""
    return str(Path(out).parent / name)


@functools.cache
def _env() -> envs.EpuckEnv:
    """One environment for the cases (made before each case: making it compiles)."""
    return envs.make("world1")


# name: (call taking the output folder, expected message fragment, is it a type error?)
CASES = {
    # -- wrong types that silently changed the experiment
    "ablate share 'no'": (lambda o: x.ablate(o, share="no"), "--share must be True or False", 1),
    "reproduce collision_cap 1.5": (
        lambda o: x.reproduce(o, collision_cap=1.5),
        "--collision-cap must be an integer, got float 1.5",
        1,
    ),
    "sweep records 'yes'": (
        lambda o: x.sweep(o, grid=GRID, records="yes"),
        "--records must be True or False, got str 'yes'",
        1,
    ),
    "trials tau_cap '30'": (
        lambda o: x.trials("SIE", tau_cap="30"),
        "--tau-cap must be a number, got str '30'",
        1,
    ),
    "render r.txt": (
        lambda o: x.render(_beside(o, "r.txt")),
        r"r.txt: expected a file name ending in .png or .pdf",
        0,
    ),
    "render robots 10**9": (
        lambda o: x.render(_beside(o, "r.png"), robots=10**9),
        r"--robots x --steps \d+ needs about .* GB of memory",
        0,
    ),
    # -- calls that crashed inside the library
    "trials trials '2'": (lambda o: x.trials("SIE", trials="2"), "--trials must be an integer", 1),
    "trials seed 'a'": (lambda o: x.trials("SIE", seed="a"), "--seed must be an integer", 1),
    "trials out 123": (lambda o: x.trials("SIE", out=123), "--out must be a path, got int", 1),
    "trials seeds 123": (lambda o: x.trials("SIE", seeds=123), "--seeds must be a path", 1),
    "trials plot 3": (lambda o: x.trials("SIE", plot=3), "--plot must be True, False or a", 1),
    "trials plot True without out": (
        lambda o: x.trials("SIE", plot=True),
        "plot=True shows the plot in a notebook",
        0,
    ),
    "trials progress 'no'": (lambda o: x.trials("HDC", progress="no"), "--progress must be", 1),
    "reproduce None": (lambda o: x.reproduce(None), "--out must be a folder's path, got None", 1),
    "reproduce trials '4'": (lambda o: x.reproduce(o, trials="4"), "--trials must be an int", 1),
    "reproduce worlds 123": (lambda o: x.reproduce(o, worlds=123), "--worlds must be a list", 1),
    "reproduce worlds [1]": (lambda o: x.reproduce(o, worlds=[1]), "each of --worlds must be", 1),
    "reproduce baseline 3": (
        lambda o: x.reproduce(o, baseline=3),
        "--baseline must be True, False or a folder of weights, got int 3",
        1,
    ),
    "reproduce evolve 'yes'": (lambda o: x.reproduce(o, evolve="yes"), "--evolve must be", 1),
    "evolve config 'x'": (lambda o: x.evolve(o, config="x"), "config must be a GAConfig", 1),
    "evolve None": (lambda o: x.evolve(None), "evolve's out must be a folder's path", 1),
    "evolve seed '0'": (lambda o: x.evolve(o, seed="0"), "seed must be an integer, got str", 1),
    "evolve resume 1": (lambda o: x.evolve(o, resume=1), "resume must be True or False", 1),
    "sweep slots 'a'": (lambda o: x.sweep(o, grid=GRID, slots="a"), "--slots must be an int", 1),
    "sweep grid [123]": (lambda o: x.sweep(o, grid=[123]), "--grid must be axis specs", 1),
    "sweep noise ['a']": (lambda o: x.sweep(o, noise=["a"]), "--noise must be a number", 1),
    "render steps '5'": (
        lambda o: x.render(_beside(o, "r.png"), steps="5"),
        "--steps must be an",
        1,
    ),
    "render fps '25'": (
        lambda o: x.render(_beside(o, "r.png"), fps="25"),
        "--fps must be a number",
        1,
    ),
    "env.reset(None)": (lambda o: _env().reset(None), r"key must be a PRNG key", 1),
    "run_trials slots 'a'": (
        lambda o: run_trials(
            envs.load_world("world1"), {"HDC": make_system("HDC")}, 2, 0, slots="a"
        ),
        "slots must be an integer, got str 'a'",
        1,
    ),
    "make_trials a dict": (lambda o: make_trials({}), "config must be a TrialsConfig", 1),
    "load_seed 3": (lambda o: load_seed(3), "load_seed's path must be a seed directory", 1),
    # -- a string where a list of names is: comma-separated names
    "ablate variants 'ours,nope'": (
        lambda o: x.ablate(o, variants="ours,nope"),
        r"--variants: unknown variant\(s\) \['nope'\]",
        0,
    ),
    "sweep grid a string is one axis": (
        lambda o: x.sweep(o, grid="k1=0:1:2", system="HDC"),
        "--grid k1: HDC does not use it",
        0,
    ),
    "sweep noise_kinds 'ir,nope'": (
        lambda o: x.sweep(o, noise=[1.0], noise_kinds="ir,nope"),
        "--noise-kinds: one or more of",
        0,
    ),
    # -- sizes that allocate: bounded by the memory, as --trials is
    "sweep grid points": (
        lambda o: x.sweep(o, grid=["k1=0:1:1000000", "k2=0:1:1000000"]),
        "--grid points 1000000000000 needs about",
        0,
    ),
    "trials 10**12": (lambda o: x.trials("SIE", trials=10**12), "--trials 10+ needs about", 0),
    # -- the environment: types, signs and the hysteresis' order
    "make collision_penalty -1": (
        lambda o: envs.make(collision_penalty=-1.0),
        "EnvParams.collision_penalty must be a number >= 0, got -1.0",
        0,
    ),
    "make auto_reset 'no'": (
        lambda o: envs.make(auto_reset="no"),
        "auto_reset must be True or False",
        1,
    ),
    "make levels below the IR floor": (
        lambda o: envs.make(collision_level=0.9, clear_level=0.1),
        r"EnvParams.clear_level must exceed 67.19, the IR reading with nothing in range",
        0,
    ),
    "make levels inverted": (
        lambda o: envs.make(collision_level=200.0, clear_level=250.0),
        r"EnvParams.clear_level \(250.0\) must be <= collision_level \(200.0\)",
        0,
    ),
    "make finish_bonus True": (
        lambda o: envs.make(finish_bonus=True),
        "EnvParams.finish_bonus must be a number, got bool True",
        1,
    ),
    "make reset_pool True": (lambda o: envs.make(reset_pool=True), "reset_pool must be a pos", 1),
    "make world 3": (lambda o: envs.make(3), "world must be a world's name", 1),
    "EpuckEnv auto_reset 'no'": (
        lambda o: envs.EpuckEnv(_env().default_params, auto_reset="no"),
        "auto_reset must be True or False",
        1,
    ),
}


@contextlib.contextmanager
def _no_compile():
    """Fails the test if JAX compiles a program within the block."""
    seen = []

    def listen(event: str, duration: float, **kwargs) -> None:
        if event in _COMPILES:
            seen.append(event)

    jax.monitoring.register_event_duration_secs_listener(listen)
    try:
        yield seen
    finally:
        jax.monitoring.unregister_event_duration_listener(listen)


@pytest.mark.parametrize("case", list(CASES))
def test_each_bad_argument_is_refused_in_one_line_before_any_work(case, tmp_path):
    call, message, is_type = CASES[case]
    out = tmp_path / "out"
    _env()
    with _no_compile() as compiled, pytest.raises(ValueError) as info:
        call(str(out))
    text = str(info.value)
    assert re.search(message, text), text
    assert "\n" not in text
    assert isinstance(info.value, TypeError) == bool(is_type), type(info.value)
    assert not out.exists() and list(tmp_path.iterdir()) == []  # nothing written
    assert compiled == [], f"{case}: compiled before refusing"


def test_a_bool_is_no_number_and_names_may_be_one_string():
    with pytest.raises(ArgumentTypeError, match="n must be an integer, got bool True"):
        check_type(True, int, "n", "an integer")
    check_type(True, bool | int, "n", "a switch")  # bool named: accepted
    assert check_names("world1,world2", "w") == ["world1", "world2"]
    assert check_names("real", "w") == ["real"] and check_names(("a",), "w") == ["a"]
    assert protocol.check_worlds("world1,world2") == ["world1", "world2"]
    assert [v.name for v in ablation.select(check_names("ours", "v"))] == ["ours"]
    assert protocol.check_caps(30, 5) == (30.0, 5)
