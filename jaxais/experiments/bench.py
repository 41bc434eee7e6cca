"""The simulator's benchmark suite (``scripts/bench.py``): every figure into one JSON document.

Rates are robot-steps per second, best of ``repeats`` timed calls after a warm-up. JAX is
imported by the benchmarks, not here, so :func:`force_host_devices` can set the device count.
"""

from __future__ import annotations

import contextlib
import datetime
import functools
import itertools
import json
import os
import platform
import statistics
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from jaxais import children
from jaxais.io import RUN_BYTES, atomic_write_json, check_memory

SCHEMA = "jaxais-bench/1"
DEVICE_FLAG = "--xla_force_host_platform_device_count"

QUICK = dict(steps=50, repeats=2, batches=(1, 30, 1000), numpy_robots=4, numpy_steps=5,
             matmul=512, controller_batches=(30,), controller_steps=50,
             loop_trials=(30,))  # fmt: skip
SPEEDUP_BATCH = 30  # compared with NumPy: a population of 30, as in the GA
RESET_CHUNK = 1000  # robots reset in one call; larger batches repeat them (same work per step)
SHARDING_HELPS = 1.1  # sharding "helps" when this much faster at the largest batch (noise)
FLOPS_BATCH = 1000  # the largest batch whose single-step program is cost-analysed
CRUISE, GAIN = 300.0, 0.3  # the policy: wheels = CRUISE -/+ GAIN x (right IR - left IR)


@dataclass(frozen=True)
class ScriptRun:
    """A command ``--scripts`` times: JSON key, script (``jaxais.scripts.NAME`` or an absolute
    path) and flags, its ``--out`` name (in a fresh folder) and wall-time target (s)."""

    name: str
    argv: tuple[str, ...]
    out: str
    target_s: float


SCRIPT_RUNS: tuple[ScriptRun, ...] = (
    # The default LTL run and 30 SIE trials in world1 with the shipped seed, compiles included.
    ScriptRun("evolve", ("evolve.py",), "ltl", 120.0),
    ScriptRun("trials", ("trials.py", "--system", "SIE", "--world", "world1", "--trials", "30"),
              "results.json", 15.0),
)  # fmt: skip


@dataclass(frozen=True)
class BenchConfig:
    """What to measure (``scripts/bench.py --help``); made by :func:`bench_config`."""

    world: str = "world1"
    steps: int = 200
    batches: tuple[int, ...] = (1, 30, 1000, 10000)
    repeats: int = 5
    quick: bool = False
    numpy_robots: int = 30
    numpy_steps: int = 20
    matmul: int = 2048
    controller_batches: tuple[int, ...] = (30, 1000)
    controller_steps: int = 500
    loop_trials: tuple[int, ...] = (30, 300, 1000)
    scripts: int = 0


def _sizes(value: str | Sequence[int], flag: str) -> tuple[int, ...]:
    """Sorted distinct batch sizes from ``"1,30"`` or a sequence (one-line ValueErrors)."""
    items = value.split(",") if isinstance(value, str) else value
    try:
        sizes = sorted({int(b) for b in items if str(b).strip()})
    except ValueError:
        raise ValueError(f"{flag} must be comma-separated integers, got {value!r}") from None
    if not sizes or sizes[0] <= 0:
        raise ValueError(f"{flag} must be positive integers, got {value!r}")
    return tuple(sizes)


def bench_config(quick: bool = False, **values: Any) -> BenchConfig:
    """A checked :class:`BenchConfig` (None: the default or :data:`QUICK`'s); batch sizes may be
    ``"1,30,1000"``; one-line ValueError on a bad value."""
    values = (QUICK if quick else {}) | {k: v for k, v in values.items() if v is not None}
    for name in ("steps", "repeats", "numpy_robots", "numpy_steps", "matmul", "controller_steps"):
        if values.get(name, 1) <= 0:
            flag = "--" + name.replace("_", "-")
            raise ValueError(f"{flag} must be a positive integer, got {values[name]}")
    if values.get("scripts", 0) < 0:
        raise ValueError(
            f"--scripts must be a count of runs (0 skips them), got {values['scripts']}"
        )
    if str(values.get("loop_trials")) in ("0", "(0,)"):  # --loop-trials 0 skips the loop rates
        values["loop_trials"] = ()
    for name in ("batches", "controller_batches", "loop_trials"):
        if values.get(name, ()) != ():
            values[name] = _sizes(values[name], "--" + name.replace("_", "-"))
    config = BenchConfig(quick=quick, **values)
    for flag, count, each in (
        ("--batches", max(config.batches), RUN_BYTES),
        ("--controller-batches", max(config.controller_batches), RUN_BYTES),
        ("--loop-trials", max(config.loop_trials, default=1), RUN_BYTES),
        ("--numpy-robots x --numpy-steps", config.numpy_robots * config.numpy_steps, 64),
        ("--matmul squared", config.matmul**2, 12),  # three float32 matrices
    ):
        check_memory(count, each, flag)
    return config


def force_host_devices(n: int) -> None:
    """Make XLA's CPU backend expose ``n`` devices (must run before JAX is imported)."""
    if n <= 0:
        raise ValueError(f"--devices must be a positive integer, got {n}")
    if "jax" in sys.modules:
        raise ValueError("--devices must be applied before JAX is imported")
    flags = [f for f in os.environ.get("XLA_FLAGS", "").split() if not f.startswith(DEVICE_FLAG)]
    os.environ["XLA_FLAGS"] = " ".join([*flags, f"{DEVICE_FLAG}={n}"])


@dataclass
class Bench:
    """Every benchmark's input and output: ``results`` is the JSON document, ``reset`` holds
    :func:`initial`'s robots, ``environ`` the timed scripts' environment."""

    config: BenchConfig
    world: Any
    params: Any
    environ: dict[str, str] = field(default_factory=dict)
    results: dict[str, Any] = field(default_factory=dict)
    reset: Any = None
    notes: list[str] = field(default_factory=list)


def _timed(fn: Callable[[], Any], repeats: int) -> dict[str, Any]:
    """``best_s``, ``median_s``, ``times_s`` of ``repeats`` calls after a warm-up; ``cpu_per_wall``
    (about the cores kept busy)."""
    import jax

    jax.block_until_ready(fn())
    times = []
    cpu0 = time.process_time()
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(fn())
        times.append(time.perf_counter() - t0)
    cpu = time.process_time() - cpu0
    return {
        "best_s": min(times),
        "median_s": statistics.median(times),
        "times_s": times,
        "cpu_per_wall": cpu / sum(times),
    }


def policy(ir, xp):
    """One robot's wheel speeds [2] from its IR readings [8] (``xp``: ``jnp`` or ``np``): steer
    away from the nearer side."""
    turn = GAIN * (ir[0] + ir[1] - ir[6] - ir[7])
    return xp.stack([CRUISE - turn, CRUISE + turn])


def make_rollout(n_steps: int, sharding: Any = None) -> Callable[..., Any]:
    """``rollout(key, state, obs, world, params) -> (state, obs)``: ``n_steps`` batched steps,
    keys and wheels constrained to ``sharding`` (None: one device)."""
    import jax
    import jax.numpy as jnp

    from jaxais import envs

    v_step = jax.vmap(envs.step, in_axes=(0, 0, 0, None, None))
    v_policy = jax.vmap(lambda obs: policy(obs.ir, jnp))

    def rollout(key, state, obs, world, params):
        n = state.t.shape[0]

        def body(carry, k):
            state, obs = carry
            keys = jax.random.split(k, n)
            wheels = v_policy(obs).astype(jnp.float32)
            if sharding is not None:
                keys, wheels = jax.lax.with_sharding_constraint((keys, wheels), sharding)
            return v_step(keys, state, wheels, world, params), None

        carry, _ = jax.lax.scan(body, (state, obs), jax.random.split(key, n_steps))
        return carry  # the final observation keeps every step's sensing alive

    return jax.jit(rollout)


def initial(b: Bench, n: int) -> tuple[Any, Any]:
    """(states, observations) of ``n`` robots after reset (NumPy-tiled from one compiled call)."""
    import jax
    import numpy as np

    from jaxais import envs

    chunk = min(max(*b.config.batches, b.config.numpy_robots), RESET_CHUNK)
    if b.reset is None:

        def reset_observe(key):
            k_reset, k_obs = jax.random.split(key)
            s = jax.vmap(envs.reset, in_axes=(0, None, None))(
                jax.random.split(k_reset, chunk), b.world, b.params
            )
            o = jax.vmap(envs.observe, in_axes=(0, 0, None, None))(
                jax.random.split(k_obs, chunk), s, b.world, b.params
            )
            return s, o

        b.reset = jax.device_get(jax.jit(reset_observe)(jax.random.key(0)))
    return jax.tree.map(lambda x: x[np.arange(n) % chunk], b.reset)


def bench_machine(b: Bench) -> None:
    """``machine``: what the figures were measured on."""
    import jax
    import jaxlib
    import numpy as np

    def cpu_model() -> str:
        with contextlib.suppress(OSError):
            for line in Path("/proc/cpuinfo").read_text().splitlines():
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
        return platform.processor() or platform.machine()

    memory = None
    with contextlib.suppress(ValueError, OSError, AttributeError):
        memory = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    affinity = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None
    b.results["machine"] = {
        "platform": platform.platform(),
        "machine": platform.machine(),
        "processor": cpu_model(),
        "cpu_count": os.cpu_count(),
        "cpus_available": affinity,
        "memory_bytes": memory,
        "python": sys.version.split()[0],
        "numpy": np.__version__,
        "jax": jax.__version__,
        "jaxlib": getattr(jaxlib, "__version__", None) or jaxlib.version.__version__,
        "backend": jax.default_backend(),
        "device_count": jax.device_count(),
        "device_kinds": sorted({d.device_kind for d in jax.devices()}),
        "xla_flags": os.environ.get("XLA_FLAGS", ""),
        "load_average_start": list(os.getloadavg()),
        "date": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
    }


def _bench_batches(b: Bench, batches: list[int], sharding: Any = None) -> dict[str, dict]:
    """Compile and time the rollout at each batch size; {batch: {compile_s, best, median}}."""
    import jax

    out: dict[str, dict] = {}
    key = jax.random.key(1)
    steps = b.config.steps
    for n in batches:
        state, obs = initial(b, n)
        # On the device(s) before timing: no host-to-device copy inside the timed calls.
        state, obs = jax.device_put((state, obs), sharding)
        rollout = make_rollout(steps, sharding)
        t0 = time.perf_counter()
        compiled = rollout.lower(key, state, obs, b.world, b.params).compile()
        compile_s = time.perf_counter() - t0
        t = _timed(
            functools.partial(compiled, key, state, obs, b.world, b.params), b.config.repeats
        )
        out[str(n)] = {
            "compile_s": compile_s,
            "steps_per_s": n * steps / t["best_s"],
            "steps_per_s_median": n * steps / t["median_s"],
            **t,
        }
    return out


def bench_jax(b: Bench) -> None:
    """``jax_steps_per_s``, ``jax_steps_per_s_median``, ``compile_s`` per batch size."""
    runs = _bench_batches(b, b.config.batches)
    b.results["jax_steps_per_s"] = {k: v["steps_per_s"] for k, v in runs.items()}
    b.results["jax_steps_per_s_median"] = {k: v["steps_per_s_median"] for k, v in runs.items()}
    b.results["compile_s"] = {k: v["compile_s"] for k, v in runs.items()}
    b.results["jax_runs"] = runs


def bench_env(b: Bench) -> None:
    """``env_steps_per_s``: ``envs.make``'s env, 64 under ``vmap``, random actions, 50-step
    episodes: ``step_env`` (no reset), ``step`` (auto-reset from the pool) and ``step_refresh``
    (``refresh_pool=True``: each auto-reset redraws the start it took)."""
    import jax

    from jaxais import envs

    n, key = 64, jax.random.key(0)

    def rate(name: str, refresh: bool) -> float:
        env = envs.make(b.config.world, max_steps_in_episode=50, refresh_pool=refresh)
        p = env.default_params
        _, state = jax.jit(jax.vmap(env.reset, in_axes=(0, None)))(jax.random.split(key, n), p)
        v_step = jax.vmap(getattr(env, name), in_axes=(0, 0, 0, None))

        @jax.jit
        def run(s, p):
            def body(s, k):
                actions = jax.random.uniform(k, (n, 2), minval=-1.0, maxval=1.0)
                return v_step(jax.random.split(k, n), s, actions, p)[1], None

            return jax.lax.scan(body, s, jax.random.split(key, b.config.steps))[0]

        return n * b.config.steps / _timed(lambda: run(state, p), b.config.repeats)["best_s"]

    rates = {"step_env": rate("step_env", False), "step": rate("step", False)}
    rates["step_refresh"] = rate("step", True)
    b.results["env_steps_per_s"] = rates
    b.notes.append(
        f"gymnax env, {n} envs: step (auto-reset) {rates['step']:,.0f} env-steps/s, step_env "
        f"{rates['step_env']:,.0f} (x{rates['step_env'] / rates['step']:.2f}), step with "
        f"refresh_pool {rates['step_refresh']:,.0f} (x{rates['step_refresh'] / rates['step']:.2f})"
    )


def bench_sharded(b: Bench) -> None:
    """``jax_steps_per_s_sharded``: the batch axis sharded over all devices (when > 1)."""
    import jax

    from jaxais.distributed import batch_sharding

    n_dev = jax.device_count()
    usable = [n for n in b.config.batches if n % n_dev == 0]
    b.results["sharding"] = {"devices": n_dev, "batches": usable}
    b.results["jax_steps_per_s_sharded"] = None
    if n_dev == 1:
        b.notes.append("one JAX device: sharded benchmark skipped (try --devices 2)")
        return
    if not usable:
        b.notes.append(f"no batch size divisible by {n_dev} devices: sharded benchmark skipped")
        return
    # The task loop's own batch sharding (jaxais.runner shards the same way).
    runs = _bench_batches(b, usable, batch_sharding())
    sharded = {k: v["steps_per_s"] for k, v in runs.items()}
    b.results["jax_steps_per_s_sharded"] = sharded
    b.results["compile_s_sharded"] = {k: v["compile_s"] for k, v in runs.items()}
    b.results["jax_runs_sharded"] = runs
    single = b.results.get("jax_steps_per_s", {})
    gain = {k: sharded[k] / single[k] for k in sharded if k in single}
    b.results["sharding"]["speedup_vs_one_device"] = gain
    if gain:
        # Judged at the largest batch, where there is most work to split; a busy machine that
        # gives this process less than the devices' worth of cores cannot show a gain.
        largest = max(gain, key=int)
        cores = runs[largest]["cpu_per_wall"]
        helps = gain[largest] > SHARDING_HELPS
        b.results["sharding"]["helps"] = helps
        b.notes.append(
            f"sharding over {n_dev} devices: x{gain[largest]:.2f} at batch {largest} "
            f"({'helps' if helps else 'does not help'} here; the sharded run kept "
            f"{cores:.2f} cores busy)"
        )


def bench_numpy(b: Bench) -> None:
    """``numpy_steps_per_s``: the tests' NumPy oracle (``tests/reference_sim.py``, a source
    checkout's) stepping robot by robot, on the same work; left out where it is absent."""
    import importlib.util

    import jax
    import numpy as np

    from jaxais import envs

    path = Path(__file__).resolve().parents[2] / "tests" / "reference_sim.py"
    if not path.is_file():  # an installed package: the oracle ships with the tests only
        b.results["numpy"] = {"skipped": f"no {path} (run from a source checkout)"}
        return
    spec = importlib.util.spec_from_file_location("reference_sim", path)
    ref = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(ref)

    n_r, n_t = b.config.numpy_robots, b.config.numpy_steps
    state, obs = initial(b, n_r)
    # The same draws a JAX step makes, made up front so that only ref_step is timed.
    keys = jax.random.split(jax.random.key(2), (n_t, n_r))
    sample = jax.jit(jax.vmap(jax.vmap(envs.sample_step_noise, in_axes=(0, None)), (0, None)))
    noise = ref.noise_to_numpy(sample(keys, b.world))
    world_np, params_np = ref.world_to_numpy(b.world), ref.params_to_numpy(b.params)
    states, observations = ref.state_to_numpy(state), ref.obs_to_numpy(obs)

    t0 = time.perf_counter()
    for i in range(n_r):
        s, o = ref.unbatch(states, i), ref.unbatch(observations, i)
        for t in range(n_t):
            step_noise = {k: v[t, i] for k, v in noise.items()}
            s, o = ref.ref_step(s, policy(o["ir"], np), step_noise, world_np, params_np)
    seconds = time.perf_counter() - t0
    b.results["numpy_steps_per_s"] = n_r * n_t / seconds
    b.results["numpy"] = {"robots": n_r, "steps": n_t, "seconds": seconds}


def bench_flops(b: Bench) -> None:
    """``flops_per_step``: XLA's cost analysis of the compiled batched single-step program."""
    import jax
    import jax.numpy as jnp

    from jaxais import envs

    v_step = jax.jit(jax.vmap(envs.step, in_axes=(0, 0, 0, None, None)))
    # One batch size (each costs a compilation): the per-robot figure hardly depends on it.
    n = max([x for x in b.config.batches if x <= FLOPS_BATCH] or [1])
    state, _ = initial(b, n)
    keys = jax.random.split(jax.random.key(3), n)
    wheels = jnp.full((n, 2), CRUISE, jnp.float32)
    ca = v_step.lower(keys, state, wheels, b.world, b.params).compile().cost_analysis()
    if isinstance(ca, list | tuple):  # older jax: one dict per computation
        ca = ca[0] if ca else {}
    ca = ca or {}
    kinds = ("flops", "transcendentals", "bytes accessed")
    per_robot = {k: float(ca[k]) / n for k in kinds if k in ca}
    flops = per_robot.get("flops")
    b.results["flops_per_step"] = flops
    b.results["cost_analysis_per_step"] = {str(n): per_robot}
    if not flops:
        b.notes.append("XLA's cost analysis reported no flops for the step")


def bench_peak(b: Bench) -> None:
    """``peak_flops``: best float32 matmul rate (``jnp.dot``, jitted) on this machine."""
    import jax
    import jax.numpy as jnp

    n = b.config.matmul
    x, y = (jax.random.normal(k, (n, n), jnp.float32) for k in jax.random.split(jax.random.key(4)))
    dot = jax.jit(jnp.dot)
    t = _timed(lambda: dot(x, y), max(b.config.repeats, 3))
    b.results["peak_flops"] = 2.0 * n**3 / t["best_s"]
    b.results["peak"] = {"matmul_size": n, "dtype": "float32", **t}


def bench_controller(b: Bench) -> None:
    """``controller_iterations_per_s``: SIE's STL controller and the simulator in the trials'
    task loop (caps off), robot-iterations/s per batch; ``..._sharded`` over several devices."""
    import jax
    import jax.numpy as jnp

    from jaxais.controllers import stl_for
    from jaxais.distributed import batch_sharding
    from jaxais.loop import EpisodeConfig
    from jaxais.runner import advance, start_batch
    from jaxais.seed import load_seed
    from jaxais.systems import make_system
    from jaxais.trials import trial_keys

    steps = b.config.controller_steps
    config = EpisodeConfig(tau_cap=1e6, collision_cap=10**9, segment=steps, chunk=25)
    system = make_system("SIE", load_seed()[0])
    layouts = [("", jax.local_devices()[:1])]
    if jax.local_device_count() > 1:
        layouts.append(("_sharded", jax.local_devices()))
    for suffix, devices in layouts:
        rates, compile_s = {}, {}
        for n in b.config.controller_batches:
            if n % len(devices):
                continue
            params = jax.tree.map(lambda a, n=n: jnp.broadcast_to(a, (n, *jnp.shape(a))), system)
            keys = trial_keys(0, "SIE", n)
            reset_keys, run_keys, params = jax.device_put((*keys, params), batch_sharding(devices))
            controller = stl_for(params)
            args = (b.world, b.params, controller, params, config)
            t0 = time.perf_counter()
            start = jax.jit(start_batch, static_argnums=(4, 6))
            start = start.lower(reset_keys, run_keys, *args).compile()
            loop = jax.jit(advance, static_argnums=(3, 5)).lower(start.out_info, *args).compile()
            compile_s[str(n)] = time.perf_counter() - t0
            batch = start(reset_keys, run_keys, b.world, b.params, params)
            t = _timed(functools.partial(loop, batch, b.world, b.params, params), b.config.repeats)
            rates[str(n)] = n * steps / t["best_s"]
        b.results[f"controller_iterations_per_s{suffix}"] = rates
        b.results[f"controller_compile_s{suffix}"] = compile_s


GA_ROBOTS = 50  # the GA's population: 5 x 10 robots in lockstep


def loop_rate(kind: str, n: int) -> dict[str, Any]:
    """One loop's rate as its script runs it, in this fresh process (:func:`bench_loops` runs
    it as a child): ``"ga"``, one full GA rollout of ``n`` random robots in ga_maze (evolve.py's
    settings: the world compiled in, one device); ``"stl"``, ``n`` SIE
    trials in world1 through :func:`jaxais.run_trials` (trials.py's: one device per core),
    tail included. Timed on a second, compiled call: robot-iterations (lockstep for the GA, live
    for the STL) per CPU-second and per wall second."""
    from jaxais import _speed

    _speed.setup(cpu_device_per_core=kind == "stl", cache=False)
    import jax
    import numpy as np

    from jaxais import envs

    if kind == "ga":
        from jaxais.ga import GAConfig, core, driver

        config = GAConfig(populations=1, robots=n)
        population = core.init(jax.random.key(0), config).population
        world = envs.load_world("ga_maze")

        def run():
            out = driver.rollout(driver.start_keys(jax.random.key(1), 1), population, world,
                                 envs.default_params(), config)  # fmt: skip
            return n * int(np.ceil(out["tau"].max() / float(envs.default_params().dt) - 1e-9))
    else:
        from jaxais import load_seed, make_system, run_trials

        world, sie = envs.load_world("world1"), make_system("SIE", load_seed()[0])

        def run():
            records = run_trials(world, {"SIE": sie}, n, 0)["SIE"].records
            return sum(r["iterations"] for r in records)

    run()  # compiled, and the pool's slot counts with it
    cpu, t0 = time.process_time(), time.perf_counter()
    iterations = run()
    cpu, wall = time.process_time() - cpu, time.perf_counter() - t0
    return {"robot_iterations": iterations, "cpu_s": cpu, "wall_s": wall,
            "per_cpu_s": iterations / cpu, "per_wall_s": iterations / wall}  # fmt: skip


def bench_loops(b: Bench) -> None:
    """``loop_rates``: the GA's loop and the STL's side by side, each in a fresh process set up
    as its script sets it up (:func:`loop_rate`), and ``stl_over_ga``, per trial count, the
    STL's CPU time per robot-iteration over the GA's (1: as fast; a regression shows)."""
    if not b.config.loop_trials:
        return
    code = "import json, sys; from jaxais.experiments.bench import loop_rate; "
    code += "print(json.dumps(loop_rate(sys.argv[1], int(sys.argv[2]))))"

    def child(kind: str, n: int) -> dict[str, Any]:
        proc = children.run([sys.executable, "-c", code, kind, str(n)], env=b.environ,
                              capture_output=True, text=True, check=False)  # fmt: skip
        if proc.returncode:
            last = (proc.stderr.strip().splitlines() or ["(nothing on stderr)"])[-1]
            raise ChildProcessError(f"loop rate {kind} {n}: exit status {proc.returncode}: {last}")
        return json.loads(proc.stdout.strip().splitlines()[-1])

    ga = child("ga", GA_ROBOTS)
    stl = {str(n): child("stl", n) for n in b.config.loop_trials}
    b.results["loop_rates"] = {
        "ga": ga | {"robots": GA_ROBOTS, "world": "ga_maze"},
        "stl": stl,
        "stl_over_ga": {n: ga["per_cpu_s"] / r["per_cpu_s"] for n, r in stl.items()},
        "units": "robot-iterations per CPU-second (GA: lockstep, a full 500 s rollout; STL: "
        "live, N SIE trials in world1 to their ends); timed on a second call, compiled",
    }


def bench_scripts(b: Bench) -> None:
    """``scripts``: :data:`SCRIPT_RUNS` ``config.scripts`` times each, alternating, in fresh
    processes with ``JAXAIS_CACHE_DIR=off``; ``within_target`` counts runs <= ``target_s``."""
    if not b.config.scripts:
        return
    from tqdm.auto import tqdm

    env = {**b.environ, "JAXAIS_CACHE_DIR": "off"}
    times: dict[str, list[float]] = {run.name: [] for run in SCRIPT_RUNS}
    bar = tqdm(total=b.config.scripts * len(SCRIPT_RUNS), desc="scripts", file=sys.stderr,
               leave=False)  # fmt: skip
    with tempfile.TemporaryDirectory(prefix="jaxais-bench-") as tmp, bar:
        for i, run in itertools.product(range(b.config.scripts), SCRIPT_RUNS):
            path = Path(run.argv[0])
            bar.set_postfix_str(path.name)
            out = Path(tmp, f"{run.name}-{i}", run.out)
            out.parent.mkdir()
            where = [str(path)] if path.is_absolute() else ["-m", f"jaxais.scripts.{path.stem}"]
            t0 = time.perf_counter()
            proc = children.run([sys.executable, *where, *run.argv[1:], "--out", str(out)],
                                  env=env, capture_output=True, text=True, check=False)  # fmt: skip
            times[run.name].append(time.perf_counter() - t0)
            if proc.returncode:
                last = (proc.stderr.strip().splitlines() or ["(nothing on stderr)"])[-1]
                raise ChildProcessError(f"--scripts: {path.name} exited with status "
                                        f"{proc.returncode}: {last}")  # fmt: skip
            bar.update()
    b.results["scripts"] = {
        run.name: {
            "command": " ".join([*run.argv, "--out", run.out]),
            "target_s": run.target_s,
            "times_s": (t := times[run.name]),
            "min_s": min(t),
            "median_s": statistics.median(t),
            "max_s": max(t),
            "within_target": sum(x <= run.target_s for x in t),
        }
        for run in SCRIPT_RUNS
    }


BENCHMARKS: list[tuple[str, Callable[[Bench], None]]] = [
    ("machine", bench_machine),
    ("jax simulator", bench_jax),
    ("gymnax env auto-reset", bench_env),
    ("sharded simulator", bench_sharded),
    ("numpy reference", bench_numpy),
    ("STL controller + simulator", bench_controller),
    ("GA and STL loops", bench_loops),
    ("flops per step", bench_flops),
    ("matmul peak", bench_peak),
    ("scripts end to end", bench_scripts),
]


def derive(b: Bench) -> None:
    """Figures computed from the others: speedup over NumPy and the fraction of peak."""
    r = b.results
    jax_rates = {int(k): v for k, v in r.get("jax_steps_per_s", {}).items()}
    if jax_rates and r.get("numpy_steps_per_s"):
        batch = min(jax_rates, key=lambda n: (abs(n - SPEEDUP_BATCH), n))
        r["speedup_vs_numpy"] = jax_rates[batch] / r["numpy_steps_per_s"]
        r["speedup_batch"] = batch
    if jax_rates and r.get("flops_per_step") and r.get("peak_flops"):
        largest = max(jax_rates)
        r["achieved_flops"] = r["flops_per_step"] * jax_rates[largest]
        r["achieved_flops_batch"] = largest
        r["fraction_of_peak"] = r["achieved_flops"] / r["peak_flops"]


def summary(b: Bench, out: str | os.PathLike[str], seconds: float) -> str:
    """A few human-readable lines about the benchmark written to ``out``."""
    r, m = b.results, b.results.get("machine", {})
    per_batch = lambda d, fmt: ", ".join(f"B={k}: {v:{fmt}}" for k, v in d.items())
    cores = lambda runs: {k: v["cpu_per_wall"] for k, v in runs.items()}
    lines = [
        f"wrote {out} in {seconds:.0f} s "
        f"({m.get('backend')} {', '.join(m.get('device_kinds', []))}, "
        f"{m.get('cpu_count')} CPUs, jax {m.get('jax')}, load {r['load_average_end'][0]:.1f})",
        f"  JAX robot-steps/s (best of {b.config.repeats}, {b.config.steps}-step scan): "
        + per_batch(r.get("jax_steps_per_s", {}), ",.0f"),
        "  compile s: " + per_batch(r.get("compile_s", {}), ".1f"),
        "  cores busy (CPU time / wall time): " + per_batch(cores(r.get("jax_runs", {})), ".2f"),
    ]
    if r.get("jax_steps_per_s_sharded"):
        lines.append(
            f"  sharded over {r['sharding']['devices']} devices: "
            f"{per_batch(r['jax_steps_per_s_sharded'], ',.0f')} (cores busy: "
            f"{per_batch(cores(r['jax_runs_sharded']), '.2f')})"
        )
    for suffix in ("", "_sharded"):
        if r.get(f"controller_iterations_per_s{suffix}"):
            lines.append(
                f"  STL controller + simulator{suffix.replace('_', ' ')}, robot-iterations/s: "
                f"{per_batch(r[f'controller_iterations_per_s{suffix}'], ',.0f')} (compile s: "
                f"{per_batch(r[f'controller_compile_s{suffix}'], '.1f')})"
            )
    if r.get("loop_rates"):
        loops = r["loop_rates"]
        lines.append(
            f"  loops, robot-iterations per CPU-s: GA {loops['ga']['per_cpu_s']:,.0f}; STL "
            + ", ".join(f"N={k}: {v['per_cpu_s']:,.0f}" for k, v in loops["stl"].items())
            + " (STL/GA cost: "
            + ", ".join(f"N={k}: {v:.1f}x" for k, v in loops["stl_over_ga"].items())
            + ")"
        )
    if "numpy_steps_per_s" in r:
        text = f"  NumPy reference: {r['numpy_steps_per_s']:,.1f} robot-steps/s"
        if "speedup_vs_numpy" in r:
            text += f"; JAX at B={r['speedup_batch']} is x{r['speedup_vs_numpy']:,.0f} faster"
        lines.append(text)
    if "fraction_of_peak" in r:
        lines.append(
            f"  {r['flops_per_step']:,.0f} flops/step x steps/s at B={r['achieved_flops_batch']}"
            f" = {r['achieved_flops'] / 1e9:.2f} GFLOP/s = {100 * r['fraction_of_peak']:.1f}% of "
            f"the {r['peak_flops'] / 1e9:.1f} GFLOP/s matmul peak"
        )
    for v in r.get("scripts", {}).values():
        lines.append(
            f"  {v['command']}: {len(v['times_s'])} runs, wall s min {v['min_s']:.1f} / median "
            f"{v['median_s']:.1f} / max {v['max_s']:.1f} (target {v['target_s']:g} s: "
            f"{v['within_target']} of {len(v['times_s'])} within)"
        )
    lines += [f"  note: {n}" for n in b.notes]
    return "\n".join(lines)


def run_bench(
    config: BenchConfig, out: str | os.PathLike[str], environ: dict[str, str] | None = None
) -> Bench:
    """Run :data:`BENCHMARKS`, write ``results`` as JSON to ``out`` and return the :class:`Bench`;
    timed scripts run in ``environ`` (default: this process's)."""
    from tqdm.auto import tqdm

    from jaxais import envs

    b = Bench(
        config=config,
        world=envs.load_world(config.world),
        params=envs.default_params(),
        environ=dict(os.environ if environ is None else environ),
    )
    names = ("steps", "batches", "repeats", "quick", "numpy_robots", "numpy_steps", "scripts",
             "loop_trials")  # fmt: skip
    b.results.update(
        schema=SCHEMA,
        config={
            "world": b.world.name,
            **{k: getattr(config, k) for k in names},
            "timing": "best of `repeats` timed calls after one warm-up call (median also given)",
            "policy": f"wheels = {CRUISE:g} -/+ {GAIN:g} * (ir0 + ir1 - ir6 - ir7)",
        },
    )
    bar = tqdm(BENCHMARKS, desc="bench", unit="bench", file=sys.stderr, leave=False)
    wall: dict[str, float] = {}
    for name, fn in bar:
        bar.set_postfix_str(name)
        t = time.perf_counter()
        fn(b)
        wall[name] = time.perf_counter() - t
    bar.close()
    derive(b)
    b.results["bench_wall_s"] = wall
    b.results["load_average_end"] = list(os.getloadavg())
    b.results["notes"] = b.notes
    atomic_write_json(out, b.results)
    return b
