"""One entry point for every estimator of an ARMAX-family model from a whole record.

``method`` names the estimator; each returns an :class:`~ehss.identification.ArmaxModel`:

========  ==============================================================
``arx``   least squares, A y = q^-d B u + e (``nc`` is ignored, C = 1)
``armax`` extended least squares refined by prediction-error minimisation
``rels``  recursive extended least squares, the paper's eqs (19)–(22)
``rml``   recursive maximum likelihood (Ljung & Söderström)
========  ==============================================================
"""

from __future__ import annotations

from typing import Any

from ehss.errors import ParameterError
from ehss.identification.batch import armax_els, arx_ls
from ehss.identification.model import ArmaxModel
from ehss.identification.rels import rels

__all__ = ["METHODS", "estimate"]

METHODS = ("arx", "armax", "rels", "rml")


def estimate(
    u: Any,
    y: Any,
    *,
    method: str,
    na: int,
    nb: int,
    nc: int,
    delay: int = 1,
    dt: float = 1.0,
) -> ArmaxModel:
    """Fit an ARMAX-family model of orders (na, nb, nc) and delay to one record.

    Parameters
    ----------
    u, y : array_like, shape (n_samples,)
        Input and output (deviations from the operating point).
    method : {"arx", "armax", "rels", "rml"}
        The estimator (see the module's table).
    na, nb, nc : int
        Orders of A, B (nb + 1 coefficients) and C.
    delay : int
        Input delay in samples.
    dt : float
        Sample period in seconds.

    Raises
    ------
    ParameterError
        For an unknown ``method``.
    """
    if method not in METHODS:
        raise ParameterError(f"method={method!r} must be one of {', '.join(METHODS)}")
    if method == "arx":
        return arx_ls(u, y, na=na, nb=nb, delay=delay, dt=dt)
    if method == "armax":
        return armax_els(u, y, na=na, nb=nb, nc=nc, delay=delay, dt=dt)
    return rels(u, y, na=na, nb=nb, nc=nc, delay=delay, dt=dt, method=method)
