"""Physical constants of the e-puck and its sensors (SPEC sections 1-2): :class:`SimParams`'
fields are traced leaves (robots with different constants are one ``vmap``); numbers that fix
a shape are module constants."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from .struct import device_array, pytree_dataclass, static_field

N_IR = 8  # IR proximity sensors, ps0..ps7
CAMERA_COLUMNS, CAMERA_ROWS = 15, 3  # camera pixels [paper]
PIXELS = CAMERA_COLUMNS * CAMERA_ROWS  # the gymnax observation's pixel counts are / PIXELS
IR_FULL_SCALE = 4095.0  # the IR reading at contact; the gymnax observation's IR is / it
OBS_NAMES = tuple(f"ps{k}" for k in range(N_IR)) + ("blue", "centroid", "goal")  # gymnax obs

# Materials of surfaces, as seen by the camera.
NONE, WALL, MARKER, GOAL = 0, 1, 2, 3
MATERIALS = {"none": NONE, "wall": WALL, "marker": MARKER, "goal": GOAL}

IR_BEARINGS_DEG = np.array([-17.0, -46.0, -90.0, -152.0, 152.0, 90.0, 46.0, 17.0])
"""Sensor bearings from the heading, degrees, + is left (ps0..ps7) [ours, e-puck geometry]."""
IR_TABLE_DIST = np.array([0.0, 0.005, 0.01, 0.015, 0.02, 0.03, 0.04, 0.05, 0.06, 0.07])
IR_TABLE_VALUE = np.array(
    [4095.0, 2133.33, 1465.73, 601.46, 383.84, 234.93, 158.03, 120.0, 104.09, 67.19]
)
"""Calibrated IR table: distance from the body rim (m) -> reading, the last beyond (SPEC 2)."""
IR_TABLE_NOISE = np.array(
    [0.002, 0.003, 0.007, 0.0406, 0.01472, 0.0241, 0.0287, 0.04225, 0.03065, 0.04897]
)
"""Relative std of the reading at each table distance: Webots' e-puck noise [paper's platform,
SPEC 2]; without it a robot can hover exactly at the 250 threshold (SPEC 6)."""


@pytree_dataclass
class SimParams:
    """Robot, sensor and integration constants, SI units: ``dt`` s [paper]; ``speed_unit`` rad/s
    per wheel speed unit [paper: 0.00683]; ``max_speed`` the wheel speed clip; ``camera_fov``
    rad [paper: 0.3]; ``ir_*``: the IR tables [10] (``ir_noise`` zeros: noise-free) and the
    sensor bearings [8], rad."""

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
