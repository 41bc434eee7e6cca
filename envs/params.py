"""Physical constants of the e-puck and its sensors (SPEC sections 1-2).

Everything here is a traced leaf, so a batch of robots with different constants is one ``vmap``.
Numbers that fix a shape (8 IR sensors, 15 x 3 camera pixels) are module constants instead.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from .struct import device_array, pytree_dataclass, static_field

N_IR = 8
"""Number of IR proximity sensors (ps0..ps7)."""
CAMERA_COLUMNS = 15
"""Camera width in pixels [paper]."""
CAMERA_ROWS = 3
"""Camera height in pixels [paper]."""
PIXELS = CAMERA_COLUMNS * CAMERA_ROWS
"""Camera pixels (45): pixel counts in the gymnax observation are divided by it."""
IR_FULL_SCALE = 4095.0
"""The IR reading at contact: IR readings in the gymnax observation are divided by it."""
OBS_NAMES = tuple(f"ps{k}" for k in range(N_IR)) + ("blue", "centroid", "goal")
"""Names of the gymnax observation's entries, in order (``jaxais.envs.gymnax``)."""

# Materials of surfaces, as seen by the camera.
NONE, WALL, MARKER, GOAL = 0, 1, 2, 3
MATERIALS = {"none": NONE, "wall": WALL, "marker": MARKER, "goal": GOAL}
MATERIAL_NAMES = {v: k for k, v in MATERIALS.items()}

IR_BEARINGS_DEG = np.array([-17.0, -46.0, -90.0, -152.0, 152.0, 90.0, 46.0, 17.0])
"""Sensor bearings from the heading, degrees, + is left (ps0..ps7) [ours, e-puck geometry]."""
IR_TABLE_DIST = np.array([0.0, 0.005, 0.01, 0.015, 0.02, 0.03, 0.04, 0.05, 0.06, 0.07])
IR_TABLE_VALUE = np.array(
    [4095.0, 2133.33, 1465.73, 601.46, 383.84, 234.93, 158.03, 120.0, 104.09, 67.19]
)
"""Calibrated e-puck IR table: distance from the body rim (m) -> reading; its last value beyond
0.07 m (Webots' e-puck, SPEC 2)."""
IR_TABLE_NOISE = np.array(
    [0.002, 0.003, 0.007, 0.0406, 0.01472, 0.0241, 0.0287, 0.04225, 0.03065, 0.04897]
)
"""Relative std of the reading at each table distance: Webots' e-puck model draws every IR
reading with it, so every simulated world has this noise [paper's platform, SPEC 2]. Without it
a robot can hover exactly at the 250 threshold (SPEC 6)."""


@pytree_dataclass
class SimParams:
    """Robot, sensor and integration constants (all scalars unless noted).

    Attributes:
        dt: control/sensor period, s [paper].
        speed_unit: rad/s of wheel rotation per speed unit [paper: 0.00683].
        wheel_radius: m. axle: wheel separation, m. body_radius: m.
        max_speed: wheel speed clip, speed units.
        camera_fov: horizontal field of view, rad [paper: 0.3].
        camera_range: m; camera_height: lens height above the floor, m.
        ir_dist: [10] table distances (m); ir_value: [10] table readings; ir_noise: [10] relative
            std of the reading at those distances (zeros for noise-free IR sensors).
        ir_bearings: [8] sensor bearings, rad.
    """

    # Static: the control period fixes loop schedules (iterations to a time cap).
    dt: float = static_field(default=0.032)
    speed_unit: float = 0.00683
    wheel_radius: float = 0.0205
    axle: float = 0.053
    body_radius: float = 0.037
    max_speed: float = 1000.0
    camera_fov: float = 0.3
    camera_range: float = 2.0
    camera_height: float = 0.03
    # Filled in by default_params(); a bare SimParams() is not meant to be used.
    ir_dist: jnp.ndarray | None = None
    ir_value: jnp.ndarray | None = None
    ir_noise: jnp.ndarray | None = None
    ir_bearings: jnp.ndarray | None = None


def default_params(**overrides: float) -> SimParams:
    """The SPEC's e-puck constants, with keyword overrides (e.g. ``speed_unit=2*np.pi/1000``)."""
    base = dict(
        ir_dist=device_array(IR_TABLE_DIST, np.float32),
        ir_value=device_array(IR_TABLE_VALUE, np.float32),
        ir_noise=device_array(IR_TABLE_NOISE, np.float32),
        ir_bearings=device_array(np.deg2rad(IR_BEARINGS_DEG), np.float32),
    )
    unknown = set(overrides) - set(SimParams.__dataclass_fields__)
    if unknown:
        raise ValueError(f"unknown simulator parameter(s): {', '.join(sorted(unknown))}")
    for name, value in overrides.items():
        if name.startswith("ir_"):
            continue
        if not np.isfinite(value) or value <= 0:
            raise ValueError(f"simulator parameter {name}={value!r} must be a positive number")
    base.update(overrides)
    return SimParams(**base)
