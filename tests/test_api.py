"""The Python API as a notebook user meets it: bad arguments named in one line, parameters by
name with their valid ranges (for sweeps and optimisers), the CMA-ES example, results files in
pandas, and an ``evolve.py`` checkpoint read with orbax's own API (the README's snippets).

Everything but the CMA-ES example runs before any simulation is compiled.
"""

from __future__ import annotations

import dataclasses
import json
import re
import runpy
from pathlib import Path

import _stl_fixtures as F
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxais import (
    EpisodeConfig,
    GAConfig,
    NetworkParams,
    TrialsConfig,
    build_tables,
    load_seed,
    make_system,
    make_trials,
    records_frame,
    run_trials,
    save_seed,
    system_params,
    with_params,
)
from jaxais.baselines import TrainConfig
from jaxais.experiments import sweeps
from jaxais.experiments.records import FORMATS, results_document
from jaxais.immune.network import BOUNDS
from jaxais.io import ArgumentTypeError
from jaxais.systems import PARAMETERS
from jaxais.trials import TrialSet, _check_run, trial_records

ROOT = Path(__file__).resolve().parent.parent
TINY = float(np.finfo(np.float32).tiny)


def sie():
    return F.systems()["SIE"]


def trials(*args, **kw):
    """run_trials with the tests' world, SIE, 2 trials, seed 0, the short caps, unless given."""
    defaults = (F.world(), {"SIE": sie()}, 2, 0, F.CONFIG)
    return run_trials(*args, *defaults[len(args) :], **kw)


BAD = {
    "world by name": (
        lambda: trials("world1"),
        r"world must be an envs.World, got str 'world1': build it with envs.load_world",
    ),
    "world None": (lambda: trials(None), "world must be an envs.World, got NoneType"),
    "systems a System": (lambda: trials(F.world(), sie()), "systems must be a dict"),
    "systems empty": (lambda: trials(F.world(), {}), "systems is empty"),
    "system {}": (lambda: trials(F.world(), {"SIE": {}}), r"systems\['SIE'\] must be a System"),
    "system None": (lambda: trials(F.world(), {"SIE": None}), "must be a System, got NoneType"),
    "system a Seed": (
        lambda: trials(F.world(), {"SIE": F.random_seed()}),
        r"systems\['SIE'\] must be a System, got Seed: build it with make_system\('SIE'",
    ),
    "system negative k1": (
        lambda: trials(F.world(), {"SIE": sie().replace(network=NetworkParams(k1=-1.0))}),
        "NetworkParams.k1 must be >= 0, got -1.0",
    ),
    "label unknown": (lambda: trials(F.world(), {"FOO": sie()}), "unknown system label 'FOO'"),
    "trials 2.0": (lambda: trials(F.world(), {"SIE": sie()}, 2.0), "n_trials must be an integer"),
    "trials True": (lambda: trials(F.world(), {"SIE": sie()}, True), "n_trials must be an integ"),
    "trials 0": (lambda: trials(F.world(), {"SIE": sie()}, 0), "n_trials must be >= 1, got 0"),
    "trials per label missing": (
        lambda: trials(F.world(), {"SIE": sie()}, {"HDC": 2}),
        "n_trials has no count for 'SIE'",
    ),
    "seed 1.5": (lambda: trials(F.world(), {"SIE": sie()}, 2, 1.5), "seed must be an integer"),
    "config a string": (
        lambda: trials(F.world(), {"SIE": sie()}, 2, 0, "STL"),
        r"config must be an EpisodeConfig \(e.g. trials.STL_CONFIG\), got str 'STL'",
    ),
    "sim_params a string": (lambda: trials(sim_params="x"), "sim_params must be an envs.SimP"),
    "progress an int": (lambda: trials(progress=3), r"progress must have an update\(n\) method"),
    "controller a string": (lambda: trials(controller="STL"), "controller must be a Controller"),
    "make_system name 3": (lambda: make_system(3), "make_system's name must be one of SIE"),
    "make_system no seed": (lambda: make_system("SIE"), "SIE needs an LTL seed"),
    "make_system seed 3": (lambda: make_system("SIE", 3), "seed must be a Seed"),
    "make_system no such seed dir": (
        lambda: make_system("SIE", "/no/such/seed"),
        "/no/such/seed: no such seed directory",
    ),
    "make_system UIE without a set": (lambda: make_system("UIE"), "UIE needs a random set"),
    "make_system network dict": (
        lambda: make_system("HDC", network={"k1": 1.0}),
        "network must be a NetworkParams or None, got dict",
    ),
    "make_system network out of range": (
        lambda: make_system("HDC", network=NetworkParams(k3=2.0)),
        r"NetworkParams.k3 must be in \[0, 1\], got 2.0",
    ),
    "make_system readings dict": (
        lambda: make_system("HDC", readings={"hold": 1}),
        "readings must be a Readings",
    ),
    "TrialsConfig label FOO": (lambda: TrialsConfig(label="FOO"), "unknown system label 'FOO'"),
    "TrialsConfig world 3": (lambda: TrialsConfig(world=3), "TrialsConfig.world must be a wor"),
    "TrialsConfig n_trials 2.0": (lambda: TrialsConfig(n_trials=2.0), "n_trials must be an in"),
    "TrialsConfig episode str": (lambda: TrialsConfig(episode="x"), "episode must be an Episod"),
    "TrialsConfig controller": (lambda: TrialsConfig(controller="x"), "controller must be a Co"),
    "make_trials a world name": (lambda: make_trials("world1"), "config must be a TrialsConfig"),
    "make_trials' run given a Seed": (
        lambda: make_trials(TrialsConfig(n_trials=2))(jax.random.key(0), F.random_seed()),
        "params must be a System",
    ),
    "EpisodeConfig record 'yes'": (lambda: EpisodeConfig(record="yes"), "record must be a bool"),
    "EpisodeConfig collision_cap 2.5": (
        lambda: EpisodeConfig(collision_cap=2.5),
        "EpisodeConfig.collision_cap must be an integer, got 2.5",
    ),
    "EpisodeConfig finish_pixels '1'": (
        lambda: EpisodeConfig(finish_pixels="1"),
        "finish_pixels must be an integer",
    ),
    "NetworkParams k1 'a'": (
        lambda: NetworkParams(k1="a").validate(),
        "NetworkParams.k1 must be a number, got 'a'",
    ),
    "GAConfig populations '5'": (lambda: GAConfig(populations="5"), "populations must be an"),
    "load_seed 3": (lambda: load_seed(3), "load_seed's path must be a seed directory"),
    "save_seed a dict": (lambda: save_seed("/tmp/x", {}, {}), "save_seed's seed must be a Seed"),
    "build_tables a list": (lambda: build_tables([1]), "results_by_world must be a dict"),
    "with_params unknown name": (lambda: with_params(sie(), {"kk": 1.0}), "unknown parameter"),
    "system_params static name": (lambda: system_params(sie(), ["rho"]), "unknown parameter"),
}


def test_configs_take_numpy_scalars_as_python_numbers():
    # np.int64 passed EpisodeConfig's integer check, then failed "must be a positive number";
    # TrainConfig refused it as no positive integer.
    numpy = EpisodeConfig(tau_cap=np.float32(10.0), collision_cap=np.int64(5), record=np.True_)
    assert numpy == EpisodeConfig(tau_cap=10.0, collision_cap=5, record=True)
    types = [type(v) for v in (numpy.tau_cap, numpy.collision_cap, numpy.record)]
    assert types == [float, int, bool]
    with pytest.raises(ValueError, match="tau_cap must be a positive number, got -1.0"):
        EpisodeConfig(tau_cap=np.float32(-1.0))
    with pytest.raises(ValueError, match="collision_cap must be an integer, got 2.5"):
        EpisodeConfig(collision_cap=np.float64(2.5))
    train = TrainConfig(generations=np.int64(3), sigma=np.float32(0.5), hidden=np.int32(4))
    assert train == TrainConfig(generations=3, sigma=0.5, hidden=4)
    json.dumps(dataclasses.asdict(train))  # config.json


@pytest.mark.parametrize("case", list(BAD))
def test_each_bad_argument_is_one_line_naming_it(case):
    call, message = BAD[case]
    with pytest.raises(ValueError, match=message) as info:
        call()
    assert "\n" not in str(info.value)


def test_a_wrong_type_is_a_type_error_too():
    with pytest.raises(TypeError, match="world must be an envs.World") as info:
        trials("world1")
    assert isinstance(info.value, ArgumentTypeError) and isinstance(info.value, ValueError)


def test_numpy_integers_and_seed_paths_are_accepted(tmp_path):
    counts = _check_run(
        F.world(), {"SIE": sie()}, np.int64(2), np.uint32(3), F.CONFIG, None, None, None
    )
    assert counts == {"SIE": 2} and type(counts["SIE"]) is int
    assert TrialsConfig(n_trials=np.int64(3)).n_trials == 3
    path = F.write_seed(tmp_path / "seed")
    for given in (path, str(path)):
        jax.tree.map(np.testing.assert_array_equal, make_system("SIE", given), sie())


# ------------------------------------------------------------- parameters by name, their ranges


def test_clip_valid_by_hand_and_under_jit():
    assert BOUNDS["k1"] == (0.0, np.inf) and BOUNDS["k3"] == (0.0, 1.0)
    wild = NetworkParams(b=-5.0, k1=-0.3, k2=2.0, k3=1.5, Phi=0.0, initial_clones=-1.0)
    want = {"b": 0.0, "k1": 0.0, "k2": 2.0, "k3": 1.0, "Phi": TINY, "initial_clones": TINY}
    want |= {"rho": 8.0, "phi": 20.0, "penalty_idiotypic": 0.5}  # in range: unchanged
    host = wild.clip_valid().validate()
    jitted = jax.jit(NetworkParams.clip_valid)(jax.tree.map(jnp.float32, wild))
    for name, value in want.items():
        assert getattr(host, name) == value, name
        assert getattr(jitted, name) == np.float32(value), name
    assert np.isnan(NetworkParams(k2=float("nan")).clip_valid().k2)  # NaN stays: validate says
    # An optimiser's proposal through with_params, traced: clipped, never a negative constant.
    proposal = {"k1": jnp.float32(-1.0), "k2": jnp.float32(3.0), "b": jnp.float32(-2.0)}
    network = jax.jit(lambda x: with_params(sie(), x).network)(proposal)
    assert (float(network.k1), float(network.k2), float(network.b)) == (0.0, 3.0, 0.0)


def test_flat_params_round_trip_and_sweep_points_are_with_params():
    system = sie()
    params = system_params(system)
    assert list(params) == list(PARAMETERS) and params["k1"] == 0.85 and params["hold"] == 31
    back = with_params(system, params)
    jax.tree.map(np.testing.assert_array_equal, back, system)
    assert back.readings.hold.dtype == np.int32 and back.readings.alpha_on_self.dtype == bool
    moved = with_params(system, {"k1": 0.5, "hold": 3})
    assert system_params(moved, ["k1", "k2", "hold"]) == {"k1": 0.5, "k2": 1.1, "hold": 3}
    points = sweeps.grid_points([("k1", np.array([0.5, 1.5])), ("hold", np.array([3, 7]))])
    grid = sweeps.point_systems(system, points)
    for i, point in enumerate(points):
        one = with_params(system, point)
        jax.tree.map(lambda g, o, i=i: np.testing.assert_array_equal(g[i], o), grid, one)


@pytest.mark.slow
def test_cmaes_example_tunes_k1_and_k2_in_one_jitted_search():
    tune = runpy.run_path(str(ROOT / "examples" / "tune_k1_k2.py"))["tune"]
    network, history = tune(generations=2, population=4, trials=2, tau_cap=10.0)
    assert history.shape == (2,) and np.all(np.isfinite(history))
    assert float(network.k1) >= 0 and float(network.k2) >= 0
    network.validate()


# ------------------------------------------------------------------------- files tools read


def outcome_arrays(n: int, **stats) -> dict[str, np.ndarray]:
    """Outcome arrays [n] of made-up trials, as the pool returns them."""
    tau = np.linspace(10.0, 30.0, n)
    c = np.arange(n)
    return {
        "tau": tau,
        "collisions": c,
        "collisions_capped": np.minimum(c, 100),
        "fitness": (8 * c + tau) / 2,
        "failed_collisions": np.zeros(n, bool),
        "failed_time": tau >= 30.0,
        "trapped_s": np.zeros(n),
        "locked_s": np.zeros(n),
        "iterations": (tau / 0.032).astype(np.int32),
        "status": np.ones(n, np.int32),
        "boxes": np.zeros((n, 1, 2)),
        "goal": np.zeros((n, 2)),
        **stats,
    }


def test_records_frame_reads_trials_and_sweep_files(tmp_path, monkeypatch):
    rate = np.array([0.25, np.nan, 0.5])
    records = trial_records(outcome_arrays(3, idiotypic_difference_rate=rate))
    assert records[1]["idiotypic_difference_rate"] is None and "status" not in records[0]
    doc = results_document("UIE-R1", "world1", 7, TrialSet(records, None), {"command": None})
    assert next(iter(doc)) == "format" and doc["format"] == FORMATS["trials"]
    path = tmp_path / "uie.json"
    path.write_text(json.dumps(doc))
    frame = records_frame(path)
    assert len(frame) == 3 and frame["trial"].tolist() == [0, 1, 2]
    assert set(frame["label"]) == {"UIE-R1"} and set(frame["random_set"]) == {"R1"}
    assert frame["tau"].tolist() == [r["tau"] for r in records]
    assert frame["failed_by"].tolist() == [[], [], ["time"]]

    points = []
    for k1 in (0.5, 1.5):
        res = outcome_arrays(3)
        points.append({"values": {"k1": k1}, **sweeps.summarise_point(res)})
        points[-1]["trials"] = trial_records(res)
    sweep = {"format": FORMATS["sweep"], "axes": {"k1": [0.5, 1.5]}, "points": points}
    frame = records_frame(sweep)
    assert frame["k1"].tolist() == [0.5, 1.5] and frame["n"].tolist() == [3, 3]
    assert frame["tau"][0] == pytest.approx(20.0)
    assert frame["tau_low"][0] < 20.0 < frame["tau_high"][0]
    runs = records_frame(sweep, runs=True)
    assert len(runs) == 6 and runs["k1"].tolist() == [0.5] * 3 + [1.5] * 3
    gap_point = {"scale": 2.0, "systems": {"SIE": sweeps.summarise_point(outcome_arrays(3))}}
    gap = {"format": FORMATS["reality_gap"], "points": [gap_point]}
    assert records_frame(gap)[["scale", "label", "n"]].values.tolist() == [[2.0, "SIE", 3]]
    for p in points:
        del p["trials"]
    with pytest.raises(ValueError, match="kept no runs: run the sweep with --records"):
        records_frame(sweep, runs=True)
    with pytest.raises(ValueError, match="not a jaxais results file .format None"):
        records_frame({"points": []})
    (tmp_path / "bad.json").write_text("{")
    with pytest.raises(ValueError, match="bad.json: not JSON"):
        records_frame(tmp_path / "bad.json")
    monkeypatch.setitem(__import__("sys").modules, "pandas", None)
    with pytest.raises(ValueError, match="records_frame needs pandas: pip install pandas"):
        records_frame(sweep)


def test_readme_restores_an_evolve_checkpoint_with_orbax(tmp_path):
    """The README's snippet, run as written on a checkpoint GACheckpointer wrote."""
    from jaxais import ga
    from jaxais.checkpointing import GACheckpointer, state_to_tree

    config = GAConfig(populations=2, robots=4, generations=2, tau_cap=2.0)
    saved = ga.core.init(jax.random.key(0), config)
    with GACheckpointer(tmp_path / "checkpoints", {"run": "test"}, resume=False) as ck:
        ck.save(saved, config)
    blocks = re.findall(r"```python\n(.*?)```", (ROOT / "README.md").read_text(), re.S)
    (code,) = [b for b in blocks if "ocp.CheckpointManager" in b]
    namespace: dict = {}
    exec(code.replace('"out/checkpoints"', repr(str(tmp_path / "checkpoints"))), namespace)
    assert namespace["generation"] == 0 and namespace["meta"]["config"] == config.to_dict()
    want = state_to_tree(saved)
    assert sorted(namespace["state"]) == sorted(want)
    for name, value in state_to_tree(namespace["ga_state"]).items():
        np.testing.assert_array_equal(value, want[name], err_msg=name)
        np.testing.assert_array_equal(namespace["state"][name], want[name], err_msg=name)


@pytest.mark.slow
def test_readme_gymnax_snippet_runs_as_written():
    """The README's gymnax face, five lines run as they are: a step of jaxais's gymnax env."""
    import gymnax

    blocks = re.findall(r"```python\n(.*?)```", (ROOT / "README.md").read_text(), re.S)
    (code,) = [b for b in blocks if 'env = envs.make("world1")' in b]
    assert len([line for line in code.splitlines() if line.strip()]) == 5
    namespace: dict = {}
    exec(code, namespace)
    assert namespace["obs"].shape == (11,) and np.isfinite(float(namespace["reward"]))
    assert not bool(namespace["terminated"]) and not bool(namespace["truncated"])
    assert isinstance(namespace["env"], gymnax.environments.environment.Environment)
