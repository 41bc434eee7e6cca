"""jaxais.host_devices: how many CPU devices the scripts make, and that imports leave JAX idle."""

from __future__ import annotations

import os
import subprocess
import sys

import jax
import numpy as np
import pytest

from jaxais import host_devices
from jaxais.episode import _pad_batch, batch_sharding


def test_default_is_one_device_per_usable_core():
    assert host_devices.resolve({}) == host_devices.usable_cores() >= 1


@pytest.mark.parametrize("value", ["1", "2", " 8 "])
def test_jaxais_setting_is_used(value):
    assert host_devices.resolve({host_devices.ENV: value}) == int(value)


@pytest.mark.parametrize(
    "env",
    [
        {host_devices.JAX_ENV: "3", host_devices.ENV: "2"},
        {"XLA_FLAGS": "--xla_force_host_platform_device_count=3", host_devices.ENV: "2"},
    ],
    ids=["JAX_NUM_CPU_DEVICES", "XLA_FLAGS"],
)
def test_jax_own_settings_take_precedence(env):
    assert host_devices.resolve(env) is None


@pytest.mark.parametrize("value", ["0", "-1", "two", "1.5"])
def test_bad_setting_is_a_one_line_error(value):
    with pytest.raises(host_devices.DeviceCountError) as err:
        host_devices.resolve({host_devices.ENV: value})
    message = str(err.value)
    assert "\n" not in message and host_devices.ENV in message and repr(value) in message


def test_importing_jaxais_leaves_the_device_count_open():
    # The scripts choose the device count after their imports: no module may start JAX's
    # backends at import time (a module-level jit, an array constant, ...).
    code = (
        "import jaxais\n"
        "from jaxais import envs, ga, trials, checkpointing, seed, systems\n"
        "from jaxais.experiments import protocol, records, stats, claims, report, ablation\n"
        "from jaxais.experiments import plotting\n"
        # evolve.py imports these in a thread while it sets XLA_FLAGS and the device count
        "import orbax.checkpoint, matplotlib.figure, matplotlib.backends.backend_agg\n"
        "from jax._src import xla_bridge\n"
        "assert not xla_bridge._backends, 'an import started the JAX backends'\n"
        "from jaxais import host_devices\n"
        "print(host_devices.enable({'JAXAIS_CPU_DEVICES': '3'}))\n"
    )
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    env.pop(host_devices.JAX_ENV, None)
    env["JAX_PLATFORMS"] = "cpu"
    proc = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stdout.strip() == "3"


def test_batch_sharding_one_device_and_uneven_batches():
    one = jax.local_devices()[:1]
    assert batch_sharding(4, one) is None
    devices = [one[0], one[0]]  # the sharding is only built here, never used
    with pytest.raises(ValueError, match="does not split"):
        batch_sharding(3, devices)


def test_pad_batch_appends_copies_of_the_first_run():
    keys = jax.random.split(jax.random.key(0), 3)
    tree = {"x": np.arange(6.0).reshape(3, 2), "k": keys}
    padded = _pad_batch(tree, 2)
    np.testing.assert_array_equal(padded["x"], [[0, 1], [2, 3], [4, 5], [0, 1], [0, 1]])
    data = jax.random.key_data(padded["k"])
    np.testing.assert_array_equal(data[:3], jax.random.key_data(keys))
    np.testing.assert_array_equal(data[3], data[0])
    np.testing.assert_array_equal(data[4], data[0])
