"""Simulation of the rig: closed loops (:func:`simulate`), the open loop
(:func:`simulate_open_loop`) and their :class:`SimulationResult`."""

from __future__ import annotations

from ehss.simulation.core import (
    LIMIT_FLAGS,
    LOOPS,
    SimulationResult,
    SimulationState,
    simulate,
    with_control_rate,
)
from ehss.simulation.open_loop import simulate_open_loop

__all__ = ["LOOPS", "LIMIT_FLAGS", "SimulationResult", "SimulationState", "simulate",
           "simulate_open_loop", "with_control_rate"]
