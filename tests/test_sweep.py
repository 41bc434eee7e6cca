"""Parameter sweeps: the pool of runs (``jaxais.runner.run_pool``) and the grid
(``experiments.sweeps``).

The pool's runs must be those of ``make_trials`` bit for bit, whatever slot they ran in and
whenever they started; the sweep's points those of plain trials with the point's constants. All
programs are world1 under :data:`_stl_fixtures.CONFIG`'s short caps, one slot, so each compiles
once per session.
"""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import _stl_fixtures as F
import jax
import numpy as np
import pytest
from _python import call_main
from scipy import stats as sps

from jaxais.controllers import stl_for
from jaxais.experiments import sweeps as sweep
from jaxais.runner import run_pool, segment_length
from jaxais.trials import _keys, stream_id

ROOT = Path(__file__).resolve().parent.parent
N = 2


def keys(seed: int, n: int = N):
    trials = np.arange(n, dtype=np.uint32)
    return _keys(jax.random.key(seed), np.full(n, stream_id("SIE"), np.uint32), trials)


def repeated(system, n: int = N):
    return jax.tree.map(lambda a: np.repeat(np.asarray(a)[None], n, 0), system)


def pool(seed: int, system, n: int = N, **kw):
    reset_keys, run_keys = keys(seed, n)
    params = repeated(system, n)
    controller = stl_for(params)
    return run_pool(
        reset_keys, run_keys, params, F.world(), F.sim_params(), controller, F.CONFIG, **kw
    )


@pytest.mark.slow
def test_one_slot_refilled_gives_make_trials_runs_bit_for_bit():
    # One slot: trial 1 starts when trial 0 has ended, at a tick aligned to the idiotope's period
    # (120 iterations; 600 = 24 chunks). Its idiotope redraws then fall where they fall in a
    # batch that started both trials at once.
    sie = F.systems()["SIE"]
    for seed in (0, 1):
        want = jax.device_get(F.sie_trials(N)(jax.random.key(seed), sie))
        got = pool(seed, sie, slots=1, align=600)
        for k in ("iterations", "collisions", "status", "idiotypic_difference_rate", "replaced"):
            np.testing.assert_array_equal(got[k], want[k], err_msg=f"seed {seed}: {k}")
        for k in ("tau", "fitness", "trapped_s"):  # the same counts, times dt in float64 here
            np.testing.assert_allclose(got[k], want[k], rtol=1e-6, err_msg=f"seed {seed}: {k}")


@pytest.mark.slow
def test_a_pool_gives_make_trials_runs_bit_for_bit_whatever_its_groups(monkeypatch):
    """Eight runs in a pool of eight slots (lockstep groups of two, each ending its segments
    alone) and in make_trials' one batch with groups of two and of eight: every run's numbers
    are the same (a Braitenberg vehicle, whose runs end apart within a minute). The pool traces
    its start once: the trace its blank batch's shapes made serves its program."""
    from jaxais import runner
    from jaxais.controllers import BRAITENBERG, braitenberg_params
    from jaxais.loop import EpisodeConfig
    from jaxais.trials import TrialsConfig, batch_keys, make_trials

    config, n, params = EpisodeConfig(tau_cap=60.0), 8, braitenberg_params()
    trials = TrialsConfig(F.WORLD, n, "BV", BRAITENBERG, config)
    want = make_trials(trials)(jax.random.key(0), params)
    monkeypatch.setattr(runner, "GROUP", n)  # one lockstep group of all eight (a fresh trace)
    whole = make_trials(trials)(jax.random.key(0), params)
    reset_keys, run_keys = batch_keys(0, (("BV", n),))
    traces = []
    start_batch = runner.start_batch
    monkeypatch.setattr(runner, "start_batch", lambda *a: traces.append(1) or start_batch(*a))
    got = run_pool(reset_keys, run_keys, repeated(params, n), F.world(), F.sim_params(),
                   BRAITENBERG, config, slots=n, align=100)  # fmt: skip
    assert len(traces) <= 1  # one (none if this worker traced this pool's start before)
    assert len(set(np.asarray(want["iterations"]).tolist())) > 1  # the runs end apart
    for k in ("iterations", "collisions", "status"):
        np.testing.assert_array_equal(got[k], want[k], err_msg=k)
        np.testing.assert_array_equal(whole[k], want[k], err_msg=k)


def test_pool_slot_counts_are_powers_of_two_per_device():
    from jaxais.runner import pool_slots

    # The power of two at or above n, at most slots.
    assert [pool_slots(n, 1024) for n in (1, 2, 3, 5, 30, 40, 240, 300, 1000)] == [
        1, 2, 4, 8, 32, 64, 256, 512, 1024,
    ]  # fmt: skip
    assert pool_slots(10**6, 1024) == 1024 and pool_slots(10**6, 1000) == 512  # at most slots
    assert pool_slots(30, 1024, devices=2) == 32 and pool_slots(3, 1024, devices=2) == 4
    assert pool_slots(300, 1024, devices=4) == 512


def test_packed_puts_each_devices_running_slots_first_and_keeps_them_on_it():
    from jaxais.runner import packed

    running = np.array([0, 1, 0, 1, 1, 0, 0, 1], bool)
    assert packed(running).tolist() == [1, 3, 4, 7, 0, 2, 5, 6]  # in slot order, then the rest
    assert packed(running, devices=2).tolist() == [1, 3, 0, 2, 4, 7, 5, 6]  # each in its half
    rng = np.random.default_rng(0)
    for b, d in [(1, 1), (2, 2), (8, 1), (8, 2), (64, 4)]:
        running = rng.random(b) < 0.5
        order = packed(running, d)
        assert sorted(order.tolist()) == list(range(b))
        for share in np.split(np.arange(b), d):  # no slot leaves its device's share
            assert set(order[share].tolist()) == set(share.tolist())
            moved = running[order[share]]
            assert moved.tolist() == sorted(moved.tolist(), reverse=True)


def test_segment_length_is_a_common_multiple_of_about_600():
    assert segment_length(25) == 600
    assert segment_length(25, 120) == 600  # the paper's idiotope period: 5 redraws a segment
    assert segment_length(25, 7) == 700  # lcm 175, four times
    assert segment_length(25, 1000) == 1000
    assert segment_length(25, 7, about=1) == 175


def test_pool_rejects_bad_alignments_and_slot_counts():
    sie = F.systems()["SIE"]
    with pytest.raises(ValueError, match="multiple of the chunk"):
        pool(0, sie, slots=1, align=610)
    with pytest.raises(ValueError, match="slots must be >= 1"):
        pool(0, sie, slots=0)


# --------------------------------------------------------------------------------- the grid


def test_parse_axis_forms():
    name, values = sweep.parse_axis("k1=0:2:11")
    assert name == "k1"
    np.testing.assert_allclose(values, np.linspace(0, 2, 11))
    name, values = sweep.parse_axis("hold=1,10,31")
    assert name == "hold" and values.dtype == np.int32 and values.tolist() == [1, 10, 31]
    assert sweep.parse_axis("k2=1.1")[1].tolist() == [1.1]
    name, values = sweep.parse_axis("alpha_on_self=0,1")  # the network's earlier reading
    assert values.dtype == bool and values.tolist() == [False, True]


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        ("k1", "NAME=START:STOP:COUNT"),
        ("k1=", "NAME=START:STOP:COUNT"),
        ("k1=0:2", "NAME=START:STOP:COUNT"),
        ("k1=0:2:0", "1 <= COUNT <= 1e[+]06"),
        ("k1=0:1:10000000000", "1 <= COUNT <= 1e[+]06"),  # not 80 GB of linspace
        ("k1=0.5,1,0.5", "a value twice"),
        ("hold=1:1:3", "a value twice"),
        ("k1=a,b", "NAME=START:STOP:COUNT"),
        ("k1=0,inf", "finite"),
        ("kk1=0:1:2", "unknown parameter"),
        ("idiotope_period=60,120", "not traced"),
        ("hold=1.5,2", "integer parameter"),
        ("alpha_on_self=0,2", "a switch, 0 .off. or 1 .on."),
    ],
)
def test_parse_axis_errors_say_what_is_wrong(spec, message):
    with pytest.raises(ValueError, match=message):
        sweep.parse_axis(spec)


def test_axes_and_their_users_are_read_from_the_declarations():
    # The paper's systems: eqs (5)-(10) are SIE's and UIE's, the stage-1 penalty SRL's and
    # URL's, eq (4) every learning system's; bouts and penalty counts are every system's.
    assert sweep.USED_BY["k1"] == sweep.USED_BY["alpha_on_self"] == ("SIE", "UIE")
    assert sweep.USED_BY["penalty_non_idiotypic"] == ("SRL", "URL")
    assert sweep.USED_BY["sigma0_floor"] == ("SIE", "SRL", "UIE", "URL")
    assert {"hold", "encounter_gap", "count_encounters"} <= set(sweep.PARAMETERS)
    assert not {"hold", "encounter_gap", "count_encounters"} & set(sweep.USED_BY)
    for name in ("rho", "phi", "idiotope_period"):  # seeding-only, or compiled in
        assert name in sweep.FIXED and name not in sweep.PARAMETERS
    assert sweep.parse_axis("count_encounters=0,1")[1].tolist() == [False, True]


def test_grid_points_are_the_product_with_the_last_axis_fastest():
    axes = [("k1", np.array([0.5, 1.0])), ("hold", np.array([1, 2, 3], np.int32))]
    points = sweep.grid_points(axes)
    assert [(p["k1"], p["hold"]) for p in points] == [
        (0.5, 1), (0.5, 2), (0.5, 3), (1.0, 1), (1.0, 2), (1.0, 3)
    ]  # fmt: skip


def test_point_systems_set_each_value_and_keep_dtypes():
    sie = F.systems()["SIE"]
    points = [{"k1": 0.5, "hold": 3}, {"k1": 1.5, "hold": 7, "alpha_on_self": True}]
    grid = sweep.point_systems(sie, points)
    np.testing.assert_allclose(grid.network.k1, [0.5, 1.5])
    assert grid.readings.hold.tolist() == [3, 7]
    assert grid.readings.alpha_on_self.tolist() == [False, True]
    assert grid.readings.hold.dtype == np.asarray(sie.readings.hold).dtype
    np.testing.assert_array_equal(grid.paratopes[1], np.asarray(sie.paratopes))
    with pytest.raises(ValueError, match="k1 must be >= 0"):
        sweep.point_systems(sie, [{"k1": -1.0}])
    # Our readings' own checks (jaxais.immune.readings.readings), as the network's.
    for point, words in (({"hold": 0}, "hold must be an int >= 1"),
                         ({"encounter_gap": 0}, "encounter_gap must be an int >= 1"),
                         ({"sigma0_floor": 2.0}, "sigma0_floor must lie in")):  # fmt: skip
        with pytest.raises(ValueError, match=words):
            sweep.point_systems(sie, [{"hold": 3}, point])


SWEEP_ERRORS = [
    (dict(grid=["k1=0.5,1"], system="HDC"), "--grid k1: HDC does not use it (only SIE, UIE do)"),
    (dict(grid=["penalty_non_idiotypic=1"]), "penalty_non_idiotypic: SIE does not use it"),
    (dict(grid=["k1=0:1:100000", "k2=0:1:100000"]), "--grid points 10000000000 needs about"),
    (dict(grid=["k1=1"], trials=10**8), "--trials 100000000 needs about"),
    (dict(grid=["k1=1"], noise_kinds="ir"), "--noise-kinds applies to --noise only"),
    (dict(noise=[1.0, 1.0]), "--noise names a scale twice"),
    (dict(noise=[1.0], trials=10**8), "--trials 100000000 needs about"),
    (dict(noise=[1.0], noise_kinds="ir,ir"), "one or more of ir, camera, wheel, each once"),
    (dict(noise=[1.0], noise_kinds=""), "one or more of ir, camera, wheel, each once"),
    (dict(noise=[1.0], system="SIE,SIE"), "--system names a system twice"),
    (dict(noise=[1.0], system=""), "unknown system ''"),
    (dict(noise=[1.0], world=""), "no such world file"),
    (dict(noise=[1.0], contender="examples/braitenberg.py:braitenberg"), "sweeps a --grid"),
    (dict(grid=["speed=1"], system="SIE", contender="x.py:y"), "--contender replaces --system"),
    (dict(grid=["k1=1"], contender="examples/braitenberg.py:braitenberg"),
     "unknown parameter of the contender (one of avoid, speed, steer)"),
    (dict(grid=["speed=1"], contender="none.py:x"), "no such file none.py"),
]  # fmt: skip


def test_sweep_refuses_what_it_would_run_wrongly_or_not_at_all(tmp_path):
    """Each is refused before any run (with tiny caps, the old code ran them, or grew until
    the kernel killed it); nothing is written."""
    for i, (kw, words) in enumerate(SWEEP_ERRORS):
        out = tmp_path / str(i)
        with pytest.raises(ValueError) as info:
            sweep.sweep(out, **{"trials": 1, "tau_cap": 1.0, "slots": 2, **kw})
        assert words in str(info.value), (kw, str(info.value))
        assert not (out / "sweep.json").exists() and not (out / "reality_gap.json").exists()


def test_sweep_points_are_plain_trials_with_the_points_constants():
    sie = F.systems()["SIE"]
    axes = [("k1", np.array([0.85, 1.6]))]
    doc = sweep.run_sweep(
        F.world(), sie, "SIE", axes, N, 3, F.CONFIG, F.sim_params(), slots=1, records=True
    )
    assert doc["format"] == "jaxais-sweep/1"
    assert doc["runs"] == 2 * N and [p["values"] for p in doc["points"]] == [
        {"k1": 0.85}, {"k1": 1.6}
    ]  # fmt: skip
    for point in doc["points"]:
        system = sie.replace(network=sie.network.replace(k1=point["values"]["k1"]))
        plain = jax.device_get(F.sie_trials(N)(jax.random.key(3), system))
        # Each run's record (sweep.py --records) is its plain trial's.
        assert [r["iterations"] for r in point["trials"]] == plain["iterations"].tolist()
        assert [r["collisions"] for r in point["trials"]] == plain["collisions"].tolist()
        assert point["tau"]["mean"] == pytest.approx(float(np.mean(plain["tau"])), rel=1e-6)
        assert point["f"]["mean"] == pytest.approx(float(np.mean(plain["fitness"])), rel=1e-6)
        rate = float(np.mean(plain["idiotypic_difference_rate"]))
        assert point["idiotypic_difference_rate"]["mean"] == pytest.approx(rate, rel=1e-6)
    assert doc["base_values"] == {"k1": pytest.approx(0.85)}
    assert doc["robot_iterations"] > 0 and doc["robot_iterations_per_s"] > 0


BV = "BV=examples/braitenberg.py:braitenberg"  # a contender from a user's file


def test_a_contenders_parameters_are_named_by_their_key_paths():
    params = {"gain": np.float32(1.5), "net": {"w": np.zeros(3, np.float32)}, "on": np.bool_(1)}
    params["n"] = np.int32(4)
    assert sweep.leaf_kinds(params) == {"gain": float, "n": int, "on": bool}  # scalars only
    stacked = sweep.point_params(params, [{"gain": 2.0}, {"gain": 3.0, "n": 7}])
    assert stacked["gain"].dtype == np.float32 and stacked["gain"].tolist() == [2.0, 3.0]
    assert stacked["n"].dtype == np.int32 and stacked["n"].tolist() == [4, 7]
    assert stacked["net"]["w"].shape == (2, 3)  # the rest repeated per point
    assert sweep.parse_axis("n=1,2", sweep.leaf_kinds(params))[1].dtype == np.int32
    with pytest.raises(ValueError, match=r"unknown parameter of the contender \(one of gain, "):
        sweep.parse_axis("k1=1,2", sweep.leaf_kinds(params))


@pytest.mark.slow
def test_a_contenders_sweep_points_are_its_plain_trials():
    """A grid over a contender's ``speed``: each point's runs are run_trials' of the contender
    with that speed, on its label's streams (common random numbers)."""
    from jaxais.experiments.contenders import load_spec
    from jaxais.trials import run_trials

    bv = load_spec(BV)
    axes = [("speed", np.array([500.0, 650.0], np.float32))]
    doc = sweep.run_sweep(F.world(), bv.params, "BV", axes, N, 3, F.CONFIG, F.sim_params(),
                          slots=1, records=True, controller=bv.controller)  # fmt: skip
    assert doc["base_values"] == {"speed": 500.0}
    for point in doc["points"]:
        params = bv.params | {"speed": np.float32(point["values"]["speed"])}
        plain = run_trials(F.world(), {"BV": params}, N, 3, F.CONFIG, F.sim_params(),
                           controller=bv.controller)["BV"].records  # fmt: skip
        assert [r["tau"] for r in point["trials"]] == [r["tau"] for r in plain]
        assert [r["collisions"] for r in point["trials"]] == [r["collisions"] for r in plain]


def test_point_summary_intervals_by_hand():
    tau = np.array([100.0, 200.0, 300.0, 4000.0])
    c = np.array([0, 2, 150, 1])
    result = {
        "tau": tau,
        "collisions_capped": np.minimum(c, 100),
        "fitness": (8 * np.minimum(c, 100) + tau) / 2,
        "trapped_s": np.zeros(4),
        "failed_collisions": c > 100,
        "failed_time": tau >= 4000.0,
        "idiotypic_difference_rate": np.array([0.1, 0.2, np.nan, 0.3]),
    }
    s = sweep.summarise_point(result)
    lo, hi = sps.t.interval(0.95, 3, loc=tau.mean(), scale=sps.sem(tau))
    assert s["tau"]["mean"] == pytest.approx(1150.0)
    assert s["tau"]["ci"] == pytest.approx([lo, hi])
    assert s["c"]["mean"] == pytest.approx((0 + 2 + 100 + 1) / 4)
    assert s["trapped_s"]["ci"] == pytest.approx([0.0, 0.0])
    # Wilson: 2 failures of 4, z = 1.96: centre (p + z^2/2n) / (1 + z^2/n), by hand.
    z = 1.959963984540054
    centre = (0.5 + z * z / 8) / (1 + z * z / 4)
    half = z * math.sqrt(0.25 / 4 + z * z / 64) / (1 + z * z / 4)
    assert s["failure_rate"]["mean"] == 0.5
    assert s["failure_rate"]["ci"] == pytest.approx([centre - half, centre + half])
    # The NaN (a run where the rate does not apply) is left out.
    assert s["idiotypic_difference_rate"]["mean"] == pytest.approx(0.2)
    none_failed = sweep.summarise_point(result | {"failed_collisions": np.zeros(4, bool),
                                                  "failed_time": np.zeros(4, bool)})  # fmt: skip
    assert none_failed["failure_rate"]["ci"][1] == pytest.approx(z * z / (4 + z * z))


def test_noisy_world_scales_each_kind_and_caps_probabilities():
    from jaxais import envs

    real = envs.load_world("real")
    assert real.ir_noise > 0 and real.camera_miss > 0 and real.wheel_noise > 0
    double = sweep.noisy_world(real, 2.0)
    assert double.ir_noise == pytest.approx(2 * real.ir_noise)
    assert double.camera_shift == pytest.approx(2 * real.camera_shift)
    assert double.wheel_noise == pytest.approx(2 * real.wheel_noise)
    assert sweep.noisy_world(real, 1e6).camera_miss == 1.0  # a probability
    wheel_only = sweep.noisy_world(real, 0.0, ["wheel"])
    assert wheel_only.wheel_noise == 0.0 and wheel_only.ir_noise == real.ir_noise
    with pytest.raises(ValueError, match="unknown noise kind"):
        sweep.noisy_world(real, 1.0, ["sonar"])
    with pytest.raises(ValueError, match=">= 0"):
        sweep.noisy_world(real, -0.5)


def test_interpolate_on_a_two_axis_grid():
    doc = {
        "axes": {"k1": [0.0, 1.0], "k2": [0.0, 2.0]},
        "points": [{"idiotypic_difference_rate": {"mean": m}} for m in (0.0, 0.2, 0.4, 0.6)],
    }
    # Bilinear: at k1 = 0.5, k2 = 1.0 the mean of the four corners.
    assert sweep.interpolate(doc, "idiotypic_difference_rate", {"k1": 0.5, "k2": 1.0}) == (
        pytest.approx(0.3)
    )
    assert sweep.interpolate(doc, "idiotypic_difference_rate", {"k1": 2.0, "k2": 1.0}) is None


# ------------------------------------------------------------------------------- the script


def _sweep_script(*args: str, tmp: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "scripts/sweep.py", *args],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=480,
        env={"PATH": "/usr/bin:/bin", "HOME": str(tmp), "JAXAIS_DEBUG": ""},
    )


@pytest.mark.parametrize(
    ("args", "message", "library"),
    [
        (["--grid", "k9=0:1:2"], "--grid k9: unknown parameter", True),
        (["--grid", "k1=1", "--noise", "1"], "not allowed with argument", False),
        (["--noise", "0,x"], "comma-separated numbers", True),
        (["--grid", "k1=1", "--coordinator", "nohost"], "HOST:PORT", False),
    ],
)
def test_sweep_script_bad_input_is_one_line(args, message, library, tmp_path):
    # The library's checks answer once JAX has loaded: through the script's main, in this process.
    args = (*args, "--out", str(tmp_path / "o"))
    out = call_main("sweep.py", *args) if library else _sweep_script(*args, tmp=tmp_path)
    assert out.returncode == 2, out.stderr
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("sweep.py: error:") and message in lines[0]
    assert not (tmp_path / "o").exists()


def test_sweep_checks_every_argument_before_it_runs(tmp_path):
    """What the script passes on, as ``sweep.py`` passes it: a one-line ValueError (the script's
    one-line error), before anything is written."""
    cases = [
        ({"grid": ["idiotope_period=10,20"]}, "not traced"),
        ({"grid": ["k1=0:1:2", "k1=3"]}, "names a parameter twice"),
        ({"grid": ["k1=0:1:2"], "trials": 0}, "--trials must be >= 1"),
        ({"grid": ["k1=-1,1"]}, "k1 must be >= 0"),
        ({"grid": ["k1=1"], "system": "SIE,HDC"}, "one system"),
        ({"grid": ["k1=1"], "system": "XYZ"}, "unknown system 'XYZ'"),
        ({"grid": ["hold=0,1"]}, "hold must be an int >= 1"),  # as readings() says
        ({"noise": [-1.0, 1.0]}, "finite and >= 0"),
        ({"noise": [1.0, math.nan]}, "finite and >= 0"),
        ({"noise": [1.0], "noise_kinds": "ir,sonar"}, "--noise-kinds"),
    ]
    for kw, message in cases:
        with pytest.raises(ValueError, match=message) as err:
            sweep.sweep(tmp_path / "o", **kw)
        assert "\n" not in str(err.value)
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize(
    ("n_points", "n_trials", "slots", "count"),
    [(121, 30, 1024, 3), (121, 30, 64, 40), (5, 2, 1024, 1), (7, 3, 3, 7), (34, 30, 1024, 1)],
)
def test_every_chunk_is_as_wide_as_the_whole_grids_pool(n_points, n_trials, slots, count):
    # The shipped 11 x 11 sweep (30 trials, 1024 slots) ran as one pool 1024 runs wide; a chunk
    # of 1020 runs (34 points) compiled a narrower pool, whose rounding changed one run of the
    # point k1 = k2 = 1.0. Chunks are whole points, in order, each pool as wide as the whole's.
    got = sweep.chunks(n_points, n_trials, slots)
    assert [lo for lo, _ in got] == [0] + [hi for _, hi in got[:-1]] and got[-1][1] == n_points
    width = min(slots, n_points * n_trials)
    assert all(min(slots, (hi - lo) * n_trials) == width for lo, hi in got)
    assert len(got) == count
