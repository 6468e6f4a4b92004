"""Nonlinear model of one actuator channel: servo valve, actuator, load and sensors."""

from __future__ import annotations

from ehss.plant.model import STATE_NAMES, plant_parameter_vector, rest_state, static_force_state

__all__ = [
    "STATE_NAMES",
    "plant_parameter_vector",
    "rest_state",
    "static_force_state",
]
