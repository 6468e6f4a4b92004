"""Nonlinear model of one actuator channel: servo valve, actuator, load and sensors."""

from __future__ import annotations

from ehss.plant.kernels import PlantSettings, PlantState
from ehss.plant.model import STATE_NAMES, plant_settings, rest_state, static_force_state

__all__ = [
    "PlantSettings",
    "PlantState",
    "STATE_NAMES",
    "plant_settings",
    "rest_state",
    "static_force_state",
]
