"""jaxais.perception: what a controller author reads from a Percept, against hand-worked values.

Each function is jitted once at module level with fixed shapes, so no case compiles anew.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxais
from jaxais import perception as pe
from jaxais.envs.params import IR_TABLE_DIST, IR_TABLE_VALUE
from jaxais.immune import antigens, behaviours

proximity = jax.jit(pe.proximity)
centroid_offset = jax.jit(pe.centroid_offset)
clip_wheels = jax.jit(pe.clip_wheels)


def test_proximity_hand_worked():
    # (ir - 100) / 500 clipped: 350 -> 0.5, 101 -> 0.002, 600 and above -> 1, 100 and below -> 0.
    ir = jnp.array([0.0, 100.0, 101.0, 350.0, 600.0, 4095.0, 99.0, 475.0])
    want = [0.0, 0.0, 0.002, 0.5, 1.0, 1.0, 0.0, 0.75]
    np.testing.assert_allclose(proximity(ir), want, rtol=1e-6)
    assert proximity(ir).dtype == jnp.float32


def test_proximity_spans_about_6_cm_to_1_5_cm_of_the_ir_table():
    # The calibrated table: 6 cm reads about 104 (proximity ~0), 1.5 cm about 601 (1).
    reading = dict(zip(IR_TABLE_DIST.tolist(), IR_TABLE_VALUE.tolist(), strict=True))
    near, far = proximity(jnp.array([reading[0.015], reading[0.06]] + [0.0] * 6))[:2]
    assert float(near) == 1.0 and float(far) < 0.01


def test_proximity_batches_over_leading_axes():
    ir = jnp.tile(jnp.array([0.0, 350.0, 600.0, 100.0, 0.0, 0.0, 0.0, 850.0]), (3, 1))
    out = jax.jit(jax.vmap(pe.proximity))(ir)
    assert out.shape == (3, 8)
    np.testing.assert_allclose(out[2], [0, 0.5, 1, 0, 0, 0, 0, 1], rtol=1e-6)


@pytest.mark.parametrize(
    ("centroid", "blue", "want"),
    [(7.0, 5, 0.0), (14.0, 5, 1.0), (0.0, 5, -1.0), (10.5, 3, 0.5), (3.5, 1, -0.5),
     (3.0, 0, 0.0), (14.0, 0, 0.0)],
)  # fmt: skip
def test_centroid_offset_hand_worked(centroid, blue, want):
    out = centroid_offset(jnp.float32(centroid), jnp.int32(blue))
    assert float(out) == want and out.dtype == jnp.float32


def test_clip_wheels_hand_worked():
    np.testing.assert_array_equal(clip_wheels(jnp.array([1500.0, -2000.0])), [1000.0, -1000.0])
    np.testing.assert_array_equal(clip_wheels(jnp.array([300.0, -400.0])), [300.0, -400.0])


def test_constants_are_the_ones_the_network_uses():
    # One value each: the behaviours' wheel limit and centre column, the antigens' sides.
    assert pe.MAX_WHEEL_SPEED == behaviours.MAX_WHEEL_SPEED == 1000.0
    assert pe.CENTRE_COLUMN == behaviours.CENTRE_COLUMN == 7.0 == (pe.CAMERA_COLUMNS - 1) / 2
    assert pe.SENSOR_SIDE is antigens.SENSOR_SIDE
    assert (pe.OBSTACLE_THRESHOLD, pe.COLLISION_THRESHOLD) == (250.0, 2400.0)
    # Sides agree with the bearings (+ is left): right sensors point right, left ones left.
    right, rear, left = (np.equal(pe.SENSOR_SIDE, s) for s in (pe.RIGHT, pe.REAR, pe.LEFT))
    assert np.all(pe.IR_BEARINGS_DEG[right] < 0) and np.all(pe.IR_BEARINGS_DEG[left] > 0)
    assert np.all(np.abs(pe.IR_BEARINGS_DEG[rear]) > 90)
    assert len(pe.SENSOR_SIDE) == len(pe.IR_BEARINGS_DEG) == pe.N_IR


def test_exported_from_the_package_root():
    for name in ("proximity", "centroid_offset", "clip_wheels"):
        assert getattr(jaxais, name) is getattr(pe, name) and name in jaxais.__all__
    assert set(pe.__all__) <= set(vars(pe))
