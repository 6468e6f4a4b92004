"""Open-loop runs of the nonlinear plant: a given valve command or spool, no controller.

The same simulator as the closed loops (:mod:`ehss.simulation.core`) with the
controller left out, so that the plant can be checked against eqs (7) and (8).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from ehss.errors import ParameterError
from ehss.params import RigParams
from ehss.simulation.core import SimulationResult, _run

__all__ = ["simulate_open_loop"]


def simulate_open_loop(
    drive: Any,
    *,
    params: RigParams | None = None,
    fs: float | None = None,
    drive_kind: str = "spool",
    stiffness_n_m: float | None = None,
    seed: int | None = None,
    initial_state: Mapping[str, float] | None = None,
) -> SimulationResult:
    """Drive the nonlinear plant with a given valve command, without a controller.

    Parameters
    ----------
    drive : ndarray, shape (n,), or Signal
        Held (ZOH) over each period of ``fs``: the normalised spool position u
        (``drive_kind="spool"``, the valve dynamics of eq (1) are bypassed) or the valve
        command in volts (``drive_kind="command_v"``, through eq (1)). No DAC
        quantisation or clipping is applied to it; it reaches the valve after
        ``params.timing.delay_samples`` periods, as a closed loop's drive does.
    params : RigParams, optional
        Parameter set (default preset ``"default"``).
    fs : float, optional
        Rate of ``drive`` (default ``params.timing.control_rate_hz``); must divide
        ``params.timing.internal_rate_hz``.
    drive_kind : {"spool", "command_v"}
    stiffness_n_m : float, optional
        K of eq (6) (default ``params.load.stiffness_n_m``). With K > 0 the result's
        ``output`` is the load cell, else the LVDT.
    seed : int, optional
        Seed of the sensor noise.
    initial_state : mapping, optional
        Plant state overrides by name (:data:`ehss.plant.model.STATE_NAMES`).

    Returns
    -------
    SimulationResult
        With ``loop="open"`` and ``reference`` the drive.

    Notes
    -----
    Use it to check the plant against eq (7) (spool → displacement, K = 0) and eq (8)
    (spool → force Ap·PL with the specimen stiffness).
    """
    if drive_kind not in ("spool", "command_v"):
        raise ParameterError(f"drive_kind={drive_kind!r}; choose 'spool' or 'command_v'")
    if stiffness_n_m is not None and not (float(stiffness_n_m) >= 0.0):
        raise ParameterError(f"stiffness_n_m={stiffness_n_m!r} must be >= 0")
    return _run(
        "open",
        drive,
        params=params,
        fs=fs,
        seed=seed,
        initial_state=initial_state,
        spool_direct=drive_kind == "spool",
        stiffness_n_m=None if stiffness_n_m is None else float(stiffness_n_m),
    )
