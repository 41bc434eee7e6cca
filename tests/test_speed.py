"""The scripts' speed settings (``jaxais._speed``): XLA flags and the compilation cache."""

from __future__ import annotations

import os
import re
from importlib.metadata import version
from pathlib import Path

import pytest
from _python import run_python

from jaxais import _speed

SETUP = "import os, jax\nfrom jaxais import _speed\n_speed.setup()\n"


def _env(**extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", _speed.CACHE_ENV)}
    return {**env, "JAX_PLATFORMS": "cpu", **extra}


def test_importing_jaxais_leaves_the_backends_idle():
    # The scripts set XLA_FLAGS after their imports: no module may start JAX's backends at import
    # time (a module-level jit call, an array constant, ...), or XLA would never read them.
    code = (
        "import jaxais\n"
        "from jaxais import envs, ga, trials, checkpointing, seed, systems, loop, runner\n"
        "from jaxais.experiments import protocol, records, stats, claims, report, ablation\n"
        "from jaxais.experiments import plotting, evolution, diversity\n"
        "from jaxais.ga import config, core, driver\n"
        "import orbax.checkpoint, matplotlib.figure, matplotlib.backends.backend_agg\n"
        "from jax._src import xla_bridge\n"
        "assert not xla_bridge._backends, 'an import started the JAX backends'\n"
    )
    out = run_python(code, _env())
    assert out.returncode == 0, out.stderr[-2000:]


def test_flags_are_added_and_a_users_own_setting_kept(tmp_path: Path):
    code = SETUP + "print(os.environ['XLA_FLAGS'])\nprint(jax.jit(lambda x: x + 1)(1))\n"
    own = "--xla_cpu_use_fusion_emitters=true"
    out = run_python(code, _env(XLA_FLAGS=own, **{_speed.CACHE_ENV: "off"}))
    assert out.returncode == 0, out.stderr[-2000:]
    flags, result = out.stdout.split("\n")[:2]
    assert result == "2"  # XLA took the flags
    release = tuple(map(int, re.match(r"(\d+)\.(\d+)", version("jaxlib")).groups()))
    if not _speed.CHECKED_JAXLIB[0] <= release < _speed.CHECKED_JAXLIB[1]:
        assert flags == own  # an unchecked jaxlib: nothing added
        pytest.skip(f"jaxlib {version('jaxlib')} is outside the checked releases")
    assert flags.split() == [own, "--xla_cpu_experimental_ynn_fusion_type="]


def test_a_device_per_core_when_asked():
    code = (
        "import os, jax\nfrom jaxais import _speed\n"
        "_speed.setup(cpu_device_per_core=True)\n"
        "print(os.environ['XLA_FLAGS'])\nprint(jax.local_device_count())\n"
    )
    out = run_python(code, _env(**{_speed.CACHE_ENV: "off"}))
    assert out.returncode == 0, out.stderr[-2000:]
    flags, count = out.stdout.split("\n")[:2]
    assert int(count) == len(os.sched_getaffinity(0))
    assert f"{_speed.DEVICE_COUNT}={count}" in flags.split()
    # A device count the user chose is kept.
    mine = run_python(code, _env(JAX_NUM_CPU_DEVICES="3", **{_speed.CACHE_ENV: "off"}))
    assert mine.returncode == 0, mine.stderr[-2000:]
    assert mine.stdout.split("\n")[1] == "3" and _speed.DEVICE_COUNT not in mine.stdout


def test_the_cache_stores_compiled_programs_or_is_off(tmp_path: Path):
    # A fresh process: JAX initialises its cache once, at the first compile.
    code = SETUP + (
        "import jax.numpy as jnp\n"
        "print(jax.config.jax_compilation_cache_dir)\n"
        "jax.config.update('jax_persistent_cache_min_compile_time_secs', 0)\n"
        "jax.jit(lambda x: jnp.sin(x) * 2)(jnp.ones(3)).block_until_ready()\n"
    )
    out = run_python(code, _env(**{_speed.CACHE_ENV: str(tmp_path / "xla")}))
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip() == str(tmp_path / "xla")
    assert any(p.name.startswith("jit_") for p in (tmp_path / "xla").iterdir())
    off = run_python(code, _env(**{_speed.CACHE_ENV: "off"}))
    assert off.returncode == 0, off.stderr[-2000:]
    assert off.stdout.strip() == "None"
    where = SETUP + "print(jax.config.jax_compilation_cache_dir)\n"
    home = run_python(where, _env(HOME=str(tmp_path)))
    assert home.stdout.strip() == str(tmp_path / ".cache" / "jaxais" / "xla")
