"""The neural baseline: its features are the gymnax observation's, OpenES's estimate points
downhill, training is one deterministic compiled program, and the controller runs in the task
loop like SIE and HDC.

Sizes are tiny (a few generations of a few members over short episodes, two short trials) and
each program is compiled once, so the file runs in well under a minute on a 2-core CPU.
"""

from __future__ import annotations

import functools
import json
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest
from _python import call_main, run_python

from jaxais import envs
from jaxais.baselines import TrainConfig
from jaxais.baselines.neural import (
    NEURAL,
    MLPParams,
    _chunks,
    centered_ranks,
    es_gradient,
    features,
    init_mlp,
    load_params,
    make_train,
    openes,
    policy,
    policy_in_order,
    save_params,
)
from jaxais.controllers import Percept
from jaxais.loop import EpisodeConfig
from jaxais.trials import TrialsConfig, make_trials

TINY = TrainConfig(world="real", generations=3, pairs=4, episodes=2, steps=60, hidden=8)


def percept_of(ob: envs.Observation) -> Percept:
    """The task loop's percept of an observation (as ``jaxais.loop.iterate`` builds it)."""
    zero = jnp.int32(0)
    return Percept(
        m=zero,
        m_prev=zero,
        v=ob.vm,
        v_prev=jnp.float32(0.0),
        ir=ob.ir,
        blue_pixels=ob.blue_pixels,
        centroid=ob.blue_centroid,
        t=zero,
        tick=zero,
    )


# ------------------------------------------------------------------------------------ features


@pytest.mark.slow
def test_percept_features_equal_the_gymnax_observation():
    """For the same state, the controller's inputs are the environment's first 10 entries, and
    the controller's wheels are the policy's action x 1000, whether or not blue is seen."""
    env = envs.make("real", auto_reset=False)
    p = env.default_params
    params = init_mlp(jax.random.key(1), 8)

    def both(key):
        obs, state = env.reset(key, p)
        # reset_env observes with the second half of its key: the same observation again.
        ob = envs.observe(jax.random.split(key)[1], state.sim, p.world, p.sim)
        pc = percept_of(ob)
        _, wheels = NEURAL.act(key, NEURAL.init(key, params), pc, params)
        return obs, features(pc.ir, pc.blue_pixels, pc.centroid), wheels, ob.blue_pixels

    obs, feats, wheels, blue = jax.jit(jax.vmap(both))(jax.random.split(jax.random.key(0), 64))
    # The same formulas: equal to an ulp (the tests' unoptimised programs may round the two
    # divisions apart; a different scale, 1/4096 say, would be 2.4e-4 off).
    np.testing.assert_allclose(np.asarray(feats), np.asarray(obs[:, :10]), rtol=3e-7, atol=0)
    action = jax.vmap(policy_in_order, in_axes=(None, 0))(params, obs[:, :10])
    # Eager ops round apart from a fused program's multiply-adds: equal to float32 precision.
    np.testing.assert_allclose(np.asarray(wheels), 1000.0 * np.asarray(action), atol=1e-5)
    blue = np.asarray(blue)
    assert (blue > 0).any() and (blue == 0).any()  # both branches of the centroid
    assert np.all(np.asarray(feats)[blue == 0, 9] == 0.0)


def test_policy_in_order_is_the_mlp():
    params = init_mlp(jax.random.key(2), 16)
    x = np.asarray(jax.random.uniform(jax.random.key(3), (50, 10), minval=-1.0), np.float32)
    p = jax.tree.map(lambda a: np.asarray(a, np.float64), params)
    want = np.tanh(np.tanh(x @ p.w1 + p.b1) @ p.w2 + p.b2)  # float64, NumPy's own order
    got = jax.jit(jax.vmap(policy_in_order, in_axes=(None, 0)))(params, x)
    np.testing.assert_allclose(np.asarray(got), want, atol=1e-6)
    np.testing.assert_allclose(got, jax.vmap(policy, in_axes=(None, 0))(params, x), atol=1e-6)


def test_the_controllers_wheels_are_the_same_bits_in_any_batch():
    """A trial is the same run alone, in a batch or in the refilling pool only if the controller
    computes each robot's wheels the same way in every program: the MLP sums in a fixed order.
    (XLA picks a dot's order per program: with ``policy``, in a plain Python session, 21 of 30
    rows of a 30-robot batch differ from the same rows in a batch of 257, and 16 of 20 rows run
    alone; this test fails with it.)"""
    params = load_params()[0]
    k1, k2, k3 = jax.random.split(jax.random.key(4), 3)
    n = 64
    zero = jnp.zeros(n, jnp.int32)
    pcs = Percept(
        m=zero, m_prev=zero, v=zero * 1.0, v_prev=zero * 1.0, t=zero, tick=zero,
        ir=jax.random.uniform(k1, (n, 8), maxval=4095.0),
        blue_pixels=jax.random.randint(k2, (n,), 0, 46),
        centroid=jax.random.uniform(k3, (n,), maxval=14.0),
    )  # fmt: skip

    def wheels(pc):
        return NEURAL.act(jax.random.key(0), NEURAL.init(jax.random.key(0), params), pc, params)[1]

    batched = np.asarray(jax.jit(jax.vmap(wheels))(pcs))
    for size in (1, 3, 30):
        part = jax.jit(jax.vmap(wheels))(jax.tree.map(lambda a, s=size: a[:s], pcs))
        np.testing.assert_array_equal(np.asarray(part), batched[:size])
    alone = jax.jit(wheels)
    for i in range(8):
        np.testing.assert_array_equal(
            np.asarray(alone(jax.tree.map(lambda a, i=i: a[i], pcs))), batched[i]
        )


# -------------------------------------------------------------------------------------- OpenES


def test_centered_ranks():
    np.testing.assert_allclose(centered_ranks(jnp.array([3.0, 1.0, 2.0])), [0.5, -0.5, 0.0])
    np.testing.assert_allclose(centered_ranks(jnp.array([5.0, -1.0])), [0.5, -0.5])


def test_es_gradient_of_one_pair_by_hand():
    """One pair: the better member (lower fitness) ranks -1/2, the worse +1/2, so the estimate
    is -eps / (2 sigma) when mean + sigma eps is the better one, and +eps / (2 sigma) if not."""
    eps, sigma = jnp.array([[1.0, -2.0]]), 0.5
    np.testing.assert_allclose(es_gradient(eps, jnp.array([1.0, 3.0]), sigma), [-1.0, 2.0])
    np.testing.assert_allclose(es_gradient(eps, jnp.array([3.0, 1.0]), sigma), [1.0, -2.0])


def test_es_gradient_points_along_the_true_gradient():
    """On f(x) = |x - t|^2 at x = 0 the gradient is -2t; rank shaping keeps its direction."""
    t = jnp.array([1.0, -2.0, 0.5, 3.0])
    es = openes(pairs=2000, sigma=0.1, optimizer=optax.sgd(0.1))
    state = es.init(jnp.zeros(4))
    eps, population = es.ask(jax.random.key(0), state)
    fitness = jnp.sum((population - t) ** 2, axis=1)
    _, grad = es.tell(state, eps, fitness)
    cos = jnp.dot(grad, -2 * t) / (jnp.linalg.norm(grad) * jnp.linalg.norm(2 * t))
    assert cos > 0.95


def test_openes_with_adam_descends_a_quadratic():
    t = jnp.array([1.0, -2.0, 0.5, 3.0])
    es = openes(pairs=16, sigma=0.1, optimizer=optax.adam(0.1))

    @jax.jit
    def run(key):
        def gen(state, k):
            eps, population = es.ask(k, state)
            state, _ = es.tell(state, eps, jnp.sum((population - t) ** 2, axis=1))
            return state, None

        return jax.lax.scan(gen, es.init(jnp.zeros(4)), jax.random.split(key, 150))[0]

    final = run(jax.random.key(0)).mean
    assert float(jnp.sum((final - t) ** 2)) < 0.01 * float(jnp.sum(t**2))


# ------------------------------------------------------------------------------------ training


@functools.cache
def tiny_train():
    return make_train(TINY)


@pytest.mark.slow
def test_training_is_deterministic_and_finite():
    train = tiny_train()
    a, b, c = (train(jax.random.key(s)) for s in (0, 0, 1))
    for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
    assert not np.array_equal(np.asarray(a.params.w1), np.asarray(c.params.w1))
    assert a.params.w1.shape == (10, TINY.hidden)
    for name, v in a.metrics.items():
        assert v.shape == (TINY.generations,), name
        assert np.all(np.isfinite(np.asarray(v))), name
    assert np.all(np.asarray(a.metrics["fitness_best"]) <= np.asarray(a.metrics["fitness_mean"]))
    # The search mean moved: adam's first step has size about the learning rate per weight.
    start = init_mlp(jax.random.fold_in(jax.random.key(0), 0), TINY.hidden)
    assert not np.allclose(np.asarray(a.params.w1), np.asarray(start.w1))


def test_training_loops_cover_every_generation_in_twos_and_a_last_three():
    """No compiled loop of one generation (it rounds differently) unless the run has one."""
    assert _chunks(1) == [(0, 1)] and _chunks(3) == [(0, 3)]
    for n in range(2, 41):
        chunks = _chunks(n)
        assert [a for a, _ in chunks] == [0, *(b for _, b in chunks[:-1])] and chunks[-1][1] == n
        assert all(b - a == 2 for a, b in chunks[:-1]) and chunks[-1][1] - chunks[-1][0] in (2, 3)


def test_config_rejects_bad_values():
    for bad in ({"pairs": 0}, {"steps": 1.5}, {"sigma": 0.0}, {"collision_penalty": -1.0}):
        with pytest.raises(ValueError):
            TrainConfig(**bad)


# ---------------------------------------------------------------------------------- controller


@pytest.mark.slow
def test_controller_runs_under_make_trials():
    params = tiny_train()(jax.random.key(0)).params
    config = TrialsConfig(
        world="real",
        n_trials=2,
        label="NN",
        controller=NEURAL,
        episode=EpisodeConfig(tau_cap=8.0, collision_cap=100),
    )
    out = jax.device_get(make_trials(config)(jax.random.key(0), params))
    for k in ("tau", "fitness", "collisions"):
        assert out[k].shape == (2,) and np.all(np.isfinite(out[k])), k
    assert np.all(out["tau"] <= 8.0)
    assert np.all(np.isnan(out["idiotypic_difference_rate"]))


def test_weights_round_trip(tmp_path):
    params = init_mlp(jax.random.key(3), 5)
    save_params(tmp_path, params, {"seed": 3})
    loaded, info = load_params(tmp_path)
    assert info == {"seed": 3}
    for x, y in zip(jax.tree.leaves(params), jax.tree.leaves(loaded), strict=True):
        np.testing.assert_array_equal(np.asarray(x, np.float32), y)
    (tmp_path / "params.npz").write_bytes(b"not an npz")
    with pytest.raises(ValueError, match="not a trained neural controller"):
        load_params(tmp_path)


def _damage_params(d: Path, how: str) -> None:
    path = d / "params.npz"
    if how == "truncated":
        path.write_bytes(path.read_bytes()[:300])
    elif how == "a .npy":
        with open(path, "wb") as f:
            np.save(f, np.zeros(3))
    elif how == "random bytes":
        path.write_bytes(np.random.default_rng(0).bytes(2000))
    elif how == "no w2":
        with open(path, "wb") as f:
            np.savez(f, w1=np.zeros((10, 2)), b1=np.zeros(2), b2=np.zeros(2))
    else:
        (d / "config.json").write_text("[1, 2]")


@pytest.mark.parametrize(
    ("how", "words"),
    [
        ("truncated", "params.npz: not a trained neural controller's weights (not an .npz"),
        ("a .npy", "params.npz: not a trained neural controller's weights (not an .npz"),
        ("random bytes", "params.npz: not a trained neural controller's weights (not an .npz"),
        ("no w2", "params.npz: not a trained neural controller's weights ("),
        ("config.json a list", "config.json: holds a JSON list, expected an object"),
    ],
)
def test_damaged_weights_are_one_line_naming_the_file(tmp_path, how, words):
    """A UserError (a ValueError: the scripts print it as one line) naming the file, never
    zipfile's, pickle's or numpy's own words."""
    from jaxais.io import UserError

    save_params(tmp_path, init_mlp(jax.random.key(3), 2), {"seed": 3})
    _damage_params(tmp_path, how)
    with pytest.raises(UserError) as info:
        load_params(tmp_path)
    msg = str(info.value)
    assert msg.startswith(str(tmp_path)) and words in msg and "\n" not in msg, msg
    assert "pickle" not in msg


def test_evaluating_damaged_weights_writes_nothing(tmp_path):
    """``train_baseline.py --eval-only --weights DIR``: damaged weights are refused before the
    run's folder is made, so the same --out works once they are mended."""
    from jaxais.experiments.baseline import baseline
    from jaxais.io import UserError

    (tmp_path / "w").mkdir()
    save_params(tmp_path / "w", init_mlp(jax.random.key(3), 2), {"seed": 3})
    _damage_params(tmp_path / "w", "truncated")
    with pytest.raises(UserError, match="params.npz: not a trained neural controller's weights"):
        baseline(tmp_path / "out", train=False, weights=tmp_path / "w")
    assert not (tmp_path / "out").exists()


def test_collect_refuses_damaged_evaluations_naming_the_file(tmp_path):
    from jaxais.experiments.baseline import collect_baselines
    from jaxais.io import UserError

    good = {"fitness": 1.0, "failed": False}
    systems = {k: {"trials": [good]} for k in ("SIE", "HDC", "NN")}
    cases = {
        "a list": ([], {}, "evaluation.json: holds a JSON list"),
        "empty": ({}, {}, "evaluation.json: no entry worlds"),
        "no HDC": ({"worlds": {"w": {"systems": {"SIE": systems["SIE"]}}}}, {}, "systems/HDC"),
        "bad trial": (
            {"worlds": {"w": {"systems": systems | {"NN": {"trials": [{"fitness": "x"}]}}}}},
            {},
            "w NN holds no trials with fitness and failed",
        ),
        "config a list": ({"worlds": {"w": {"systems": systems}}}, [], "config.json: holds a"),
    }
    for name, (evaluation, config, words) in cases.items():
        d = tmp_path / name
        d.mkdir()
        (d / "evaluation.json").write_text(json.dumps(evaluation))
        (d / "config.json").write_text(json.dumps(config))
        with pytest.raises(UserError) as info:
            collect_baselines([d])
        assert str(info.value).startswith(str(d)) and words in str(info.value), (name, info)


def test_shipped_weights_load():
    params, info = load_params()
    assert isinstance(params, MLPParams)
    assert params.w1.shape == (10, info["config"]["hidden"])
    assert info["config"]["world"] == "ga_maze"


# -------------------------------------------------------------------------------------- script

SCRIPT = Path(__file__).resolve().parent.parent / "scripts" / "train_baseline.py"


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        (["--pairs", "0"], "--pairs must be a positive integer"),
        (["--learning-rate", "-1"], "--learning-rate must be a positive number"),
        (["--world", "nowhere"], "no built-in world or file 'nowhere'"),
        (["--eval-only", "--no-eval"], "--eval-only, which excludes --no-eval"),
        (["--weights", "w"], "--weights goes with --eval-only"),
    ],
)
def test_script_bad_flags_are_one_line_errors_without_jax(flags, message, tmp_path):
    out = run_python(
        "import runpy, sys\n"
        f"main = runpy.run_path({str(SCRIPT)!r}, run_name='train_baseline')['main']\n"
        "try:\n"
        f"    main(['--out', {str(tmp_path)!r}, *{flags!r}])\n"
        "except SystemExit as stop:\n"
        "    print(stop.code, 'jax' in sys.modules)\n"
    )
    assert out.stdout.split() == ["2", "False"], out.stderr[-2000:]
    assert out.stderr.startswith("train_baseline.py: error: ") and out.stderr.count("\n") == 1
    assert message in out.stderr


def test_script_collects_runs_into_one_table(tmp_path):
    """--collect: one row per run, SIE and HDC from the first, and the runs pooled."""

    def trials(fs, failed=()):
        return [{"fitness": f, "failed": i in failed} for i, f in enumerate(fs)]

    dirs = []
    for seed, nn in ((0, [10.0, 20.0]), (1, [30.0, 4000.0])):
        systems = {"SIE": {"trials": trials([50.0, 70.0])}, "HDC": {"trials": trials([1.0, 3.0])}}
        systems["NN"] = {"trials": trials(nn, failed=(1,) if seed else ())}
        d = tmp_path / f"s{seed}"
        d.mkdir()
        (d / "evaluation.json").write_text(json.dumps({"worlds": {"world1": {"systems": systems}}}))
        final = {"center_fitness_last_20": -20.0 - seed}
        (d / "config.json").write_text(json.dumps({"seed": seed, "final": final}))
        dirs.append(str(d))
    out = call_main("train_baseline.py", "--collect", *dirs)
    assert out.returncode == 0, out.stderr[-2000:]
    rows = out.stdout.splitlines()
    assert rows[2] == "| SIE | – | – | 60.0 (0) |" and rows[3] == "| HDC | – | – | 2.0 (0) |"
    assert rows[4] == "| NN | 0 | -20.0 | 15.0 (0) |"
    assert rows[5] == "| NN | 1 | -21.0 | 2015.0 (50) |"
    assert rows[6] == "| NN, all 2 runs pooled | – | – | 1015.0 (25) |"
    assert rows[10].startswith("| world1 | higher | 25.0 | 60.0 |")


def test_driver_writes_into_the_shipped_checkpoints_only_when_asked(tmp_path):
    """The shipped weights are never overwritten by default (the driver refuses before any
    work); the script's default --out is a fresh folder."""
    from jaxais.baselines.neural import default_params_dir
    from jaxais.experiments.baseline import evaluate_baseline, train_baseline

    shipped = default_params_dir()
    before = {p.name: p.read_bytes() for p in shipped.iterdir() if p.is_file()}
    with pytest.raises(ValueError, match="checkpoints"):
        train_baseline(shipped, TINY)
    with pytest.raises(ValueError, match="checkpoints"):
        evaluate_baseline(None, shipped / "sub")
    assert {p.name: p.read_bytes() for p in shipped.iterdir() if p.is_file()} == before
    assert not (shipped / "sub").exists()
    with pytest.raises(ValueError, match="no params.npz"):
        evaluate_baseline(tmp_path, tmp_path / "out")
