"""Compile, or load from numba's cache on disk, the kernels a command will use.

A numba kernel is compiled on its first call (seconds) or, when numba's cache on disk
holds it, loaded (a fraction of a second). A command that must not pause later (a live
session before its first block, a test run that compiles on a free core, a programme
whose strands would otherwise compile the same kernels at once) calls :func:`warm_up`
first. Each kind runs its kernels once on a small input of the types every record gives
them, so the code compiled is the code later calls run; nothing is checked.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import TypedDict

import numpy as np

from ehss._checks import check_choice

__all__ = ["WARM_UP_KINDS", "warm_up"]


class _Orders(TypedDict):
    na: int
    nb: int
    nc: int
    delay: int

#: What :func:`warm_up` can prepare: the closed-loop simulator (one kernel serves every
#: loop), batch RELS and RML (:func:`ehss.identification.rels`), the streaming
#: estimator (:class:`ehss.identification.RelsEstimator`, one sample and a block), and
#: the RELS/RML loop specialised to the given orders
#: (:func:`ehss.identification.rels.specialise_rels`; compiled when asked for only).
WARM_UP_KINDS = ("simulation", "identification", "streaming", "specialised")


def warm_up(
    kinds: Iterable[str] = ("simulation", "identification", "streaming"),
    *,
    na: int = 1,
    nb: int = 0,
    nc: int = 1,
    delay: int = 1,
    methods: Iterable[str] = ("rels", "rml"),
) -> None:
    """Compile (or load) the numba kernels of ``kinds`` now rather than on first use.

    Parameters
    ----------
    kinds : iterable of {"simulation", "identification", "streaming", "specialised"}
        Default all but ``"specialised"`` (see :data:`WARM_UP_KINDS`), whose compiled
        loop pays for long records and long-running estimators only.
    na, nb, nc, delay : int
        Orders of the estimators to prepare. The generic RELS loop serves any orders;
        give the orders a command will use so that a loop specialised to them
        (:func:`ehss.identification.rels.specialise_rels`), if numba's cache holds one, is
        the one loaded.
    methods : iterable of {"rels", "rml"}
        Estimators to prepare.

    Raises
    ------
    ParameterError
        For an unknown kind or method, or (when an estimator is prepared) impossible
        orders.

    Examples
    --------
    >>> from ehss import warm_up
    >>> warm_up(["simulation"])  # doctest: +SKIP
    """
    chosen = [check_choice(k, "kind", WARM_UP_KINDS) for k in kinds]
    orders = _Orders(na=na, nb=nb, nc=nc, delay=delay)  # the estimators check them
    chosen_methods = [check_choice(m, "method", ("rels", "rml")) for m in methods]
    if "specialised" in chosen:  # first: the estimators below then run it
        from ehss.identification.rels import specialise_rels

        specialise_rels(**orders)
    if "simulation" in chosen:
        _warm_simulation()
    if "identification" in chosen:
        _warm_identification(orders, chosen_methods)
    if "streaming" in chosen:
        _warm_streaming(orders, chosen_methods)


def _warm_simulation() -> None:
    """The closed loop on a writable reference (the one type ``simulate`` passes it)."""
    from ehss.simulation import simulate

    simulate("position", np.zeros(10), seed=0)


def _first_order_record() -> tuple[np.ndarray, np.ndarray]:
    """A noise-free first-order response to white noise: every estimator is well posed
    on it, whatever its orders."""
    from scipy.signal import lfilter

    u = np.random.default_rng(0).standard_normal(200)
    # y[k] = 0.5 y[k-1] + 0.5 u[k-1]
    return u, np.asarray(lfilter([0.0, 0.5], [1.0, -0.5], u), dtype=np.float64)


def _warm_identification(orders: _Orders, methods: list[str]) -> None:
    """Batch RELS/RML, one short fit each."""
    from ehss.identification import rels

    u, y = _first_order_record()
    for method in methods:
        rels(u, y, method=method, **orders)


def _warm_streaming(orders: _Orders, methods: list[str]) -> None:
    """The streaming estimator's one-sample step and its block update."""
    from ehss.identification import RelsEstimator

    u, y = _first_order_record()
    for method in methods:
        estimator = RelsEstimator(method=method, **orders)
        estimator.update(float(u[0]), float(y[0]))
        estimator.update_many(u[1:64], y[1:64])
