"""jaxais.loop_kernels: the small-loop threshold the GA's script gives XLA, and that XLA uses it."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from jaxais import loop_kernels

OPTION = "--xla_backend_extra_options=xla_cpu_small_while_loop_byte_threshold"


def test_default_threshold():
    assert loop_kernels.resolve({}) == loop_kernels.DEFAULT_BYTES == 512 * 1024


@pytest.mark.parametrize(("value", "expected"), [("4096", 4096), (" 7 ", 7), ("0", None)])
def test_jaxais_setting_is_used(value, expected):
    assert loop_kernels.resolve({loop_kernels.ENV: value}) == expected


@pytest.mark.parametrize("value", ["off", "OFF"])
def test_off_leaves_xla_alone(value):
    assert loop_kernels.resolve({loop_kernels.ENV: value}) is None


def test_the_users_own_extra_options_win():
    env = {"XLA_FLAGS": "--xla_backend_extra_options=xla_cpu_fold_all_constants"}
    assert loop_kernels.resolve({**env, loop_kernels.ENV: "4096"}) is None


@pytest.mark.parametrize("value", ["-1", "big", "1.5"])
def test_bad_setting_is_a_one_line_error(value):
    with pytest.raises(loop_kernels.LoopKernelError) as err:
        loop_kernels.resolve({loop_kernels.ENV: value})
    message = str(err.value)
    assert "\n" not in message and loop_kernels.ENV in message and repr(value) in message


def test_enable_after_jax_started_changes_nothing():
    import jax.numpy as jnp

    jnp.zeros(()).block_until_ready()  # this test process's backends are up
    env = {"XLA_FLAGS": "--xla_cpu_enable_fast_math=false"}
    assert loop_kernels.enable(env) is None
    assert env == {"XLA_FLAGS": "--xla_cpu_enable_fast_math=false"}


_PROBE = """
from jaxais import loop_kernels
n = loop_kernels.enable()
import os, jax, jax.numpy as jnp
loop = jax.jit(lambda x: jax.lax.fori_loop(0, 10, lambda i, y: jnp.sin(y) * 2.0 + 1.0, x))
text = loop.lower(jnp.zeros(4096)).compile().as_text()  # 16 KiB: over XLA's 1 KiB
print(n, os.environ.get("XLA_FLAGS", ""), "xla_cpu_small_call" in text, sep="|")
"""


@pytest.mark.parametrize("setting", ["", "off"])
def test_xla_compiles_a_small_loop_as_one_kernel_only_when_enabled(setting):
    # A fresh process, since XLA reads XLA_FLAGS once: with the threshold the loop is hoisted
    # into a call XLA marks xla_cpu_small_call; with ``off`` XLA's default 1 KiB leaves it.
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    env.update({loop_kernels.ENV: setting, "JAX_PLATFORMS": "cpu"})
    proc = subprocess.run(
        [sys.executable, "-c", _PROBE], capture_output=True, text=True, env=env, timeout=300
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    n, flags, hoisted = proc.stdout.strip().split("|")
    if setting == "off":
        assert (n, flags, hoisted) == ("None", "", "False")
    else:
        assert (n, flags, hoisted) == (str(512 * 1024), f"{OPTION}={512 * 1024}", "True")
