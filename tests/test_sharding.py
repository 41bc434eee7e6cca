"""The runner's batch sharding (``jaxais.distributed.batch_sharding``): the mesh of a batch.

That a sharded run gives every run's numbers of one device, its batch padded to a multiple of the
device count, is checked end to end in test_scripts_stl.py (``trials.py`` on one and on two CPU
devices) and test_distributed.py (two processes).
"""

from __future__ import annotations

import jax

from jaxais.distributed import batch_sharding


def test_batch_sharding_one_device_and_a_mesh_of_several():
    one = jax.local_devices()[:1]
    assert batch_sharding(one) is None
    sharding = batch_sharding([one[0], one[0]])  # the sharding is only built here, never used
    assert sharding.mesh.shape == {"batch": 2}
    assert sharding.spec == jax.sharding.PartitionSpec("batch")
    # By default, every process's devices.
    default = batch_sharding()
    assert (default is None) if jax.device_count() == 1 else default.mesh.size == jax.device_count()
