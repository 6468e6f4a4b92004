"""The controllers' numba kernels, for loops built around them (public).

A loop simulator (:mod:`ehss.simulation`) runs the digital controllers inside its own
kernel with these ``@njit`` step functions. Each takes the controller's coefficients (a
:class:`PidSettings` or :class:`TvcSettings`, built by
:func:`ehss.control.discrete.pid_coefficients` and
:func:`~ehss.control.discrete.tvc_coefficients`) and its memory (a :class:`PidState` or
:class:`TvcState`), does no validation, and returns the output with the next state. The
symbol table is in the implementation module, ``ehss.control._kernels``.

Examples
--------
>>> from ehss.control.discrete import pid_coefficients
>>> from ehss.control.kernels import PidState, pid_step
>>> from ehss.params import preset
>>> c = pid_coefficients(preset("default").position, 1e-3)
>>> u, st = pid_step(0.001, 0.0, PidState(0.0, 0.0, 0.0), c)
>>> bool(u == c.kp * 0.001 and st.integral_v == c.ki_dt * 0.001)
True
"""

from __future__ import annotations

from ehss.control import _kernels
from ehss.control._kernels import *  # noqa: F403  (the public face offers every kernel)

__all__ = _kernels.__all__
