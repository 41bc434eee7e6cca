"""The task loop's batch sharding (``jaxais.episode``): the mesh and the padding of a batch.

That a sharded run gives every run's numbers of one device is checked end to end in
test_scripts_stl.py (``trials.py`` on one and on two CPU devices).
"""

from __future__ import annotations

import jax
import numpy as np
import pytest

from jaxais.episode import _pad_batch, batch_sharding


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
