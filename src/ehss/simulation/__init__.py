"""Closed-loop simulation of the rig: :func:`simulate` and :class:`SimulationResult`."""

from __future__ import annotations

from ehss.simulation.core import LOOPS, SimulationResult, simulate

__all__ = ["LOOPS", "SimulationResult", "simulate"]
