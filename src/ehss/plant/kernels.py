"""The plant's numba kernels, for loops built around the plant (public).

A loop simulator (:mod:`ehss.simulation`) integrates the actuator channel with these
``@njit`` functions inside its own kernel. They take a :class:`PlantSettings` (packed
from a :class:`~ehss.params.RigParams` by :func:`ehss.plant.model.plant_settings`) and a
:class:`PlantState`, do no validation, and return new states instead of writing into
buffers. The equations and the symbol table are in the implementation module,
``ehss.plant._kernels``.

Examples
--------
>>> from ehss.params import preset
>>> from ehss.plant.kernels import clamp_state, rk4_step
>>> from ehss.plant.model import plant_settings, rest_state
>>> p = preset("default")
>>> s = plant_settings(p, stiffness_n_m=0.0, internal_dt_s=1e-4)
>>> x = clamp_state(rk4_step(rest_state(p), 0.1, s, 1e-4), s)
>>> bool(x.spool > 0.0)
True
"""

from __future__ import annotations

from ehss.plant import _kernels
from ehss.plant._kernels import *  # noqa: F403  (the public face offers every kernel)

__all__ = _kernels.__all__
