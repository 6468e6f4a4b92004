"""A model identified behind known factors, composed into the complete model.

When part of a loop is known exactly (for the rig's acceleration loop: the generator of
eq (10) and the accelerometer coupling, :func:`ehss.control.known.known_factors`), the
input is filtered through it, only the rest is identified, and the complete model is
the product:

.. math:: G(q) = F(q)\\,G_{rest}(q), \\qquad u_f = F(q)\\,u, \\quad y = G_{rest}(q)\\,u_f
"""

from __future__ import annotations

import numpy as np

from ehss.identification.model import ArmaxModel

__all__ = ["compose"]


def compose(model: ArmaxModel, num: np.ndarray, den: np.ndarray) -> ArmaxModel:
    """The complete model F(q)·G_rest(q) of a model identified behind known factors.

    With y = B/A·u_f + C/A·ξ and u_f = N/D·u, the complete ARMAX model has
    A' = D·A, B' = N·B and C' = D·C, so that the noise model C'/A' = C/A is unchanged.
    """
    num = np.asarray(num, dtype=float)
    den = np.asarray(den, dtype=float)
    meta = dict(model.meta)
    meta["known_factors"] = {"num": num.tolist(), "den": den.tolist()}
    return ArmaxModel(
        a=np.polymul(den, model.a),
        b=np.polymul(num, model.b),
        c=np.polymul(den, model.c),
        delay=model.delay,
        dt=model.dt,
        noise_variance=model.noise_variance,
        meta=meta,
    )
