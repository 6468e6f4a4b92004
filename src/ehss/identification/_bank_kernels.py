"""Numba kernel of a bank of RELS/RML estimators: many channels in one compiled loop.

A bank runs C independent estimators with the same orders, e.g. the loops of a rig
identified side by side. Its record has the channel as its innermost axis,
``rec[row, k, c]`` (rows u, y in; e, ξ̂ out, as :func:`._kernels.rels_run`'s), and each
channel keeps its own estimator block (a row of ``blocks``, laid out as
:func:`._kernels.new_block`'s). For each sample the loop runs the one per-sample step of
:mod:`._kernels` (:func:`._kernels._sample`, eqs (19)–(22) with every safeguard) on
each channel in turn: the same operations in the same order as the single-channel
loop, so each channel's results are those of a single-channel run, bit for bit.

What a bank buys: the channels' steps are independent, so the processor overlaps one
channel's chain of dependent operations (the P pass, the gain, the denominator, the
square root of (22)) with the next channel's, where a single channel waits on it;
and a streaming call carries every channel's sample, so the cost of crossing from
Python into the compiled loop (most of :meth:`RelsEstimator.update`'s time) is paid
once for all of them.

Why not one channel per SIMD lane (P[i, j, c] with the channel innermost in the
state): numba runs LLVM without its SLP vectoriser, and LLVM fully unrolls a loop of
a few (compile-time constant) iterations, such as one over 8 channels, into scalar
code before its loop vectoriser could see it. With the lane count a run-time value
the lane loop of the P pass is vectorised, but that pass stores P and g for every
entry and runs one short lane loop, with its run-time alias checks, per entry; the
forms that would store g less often (two or four rows a pass) are not vectorised at
all. Measured, the lanes pass alone costs about what the whole step of a channel
would have to cost for the bank to pay (BENCHMARKS.md, "Why the bank does not put
channels in SIMD lanes"), so the bank keeps the single-channel step.

The kernel is compiled per orders (the orders as constants, like
:func:`._kernels.specialised`) and cached on disk.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numba import types

from ehss.identification._kernels import (
    LINE,
    N_SETTINGS,
    NOISE_VAR,
    PENDING,
    RelsSettings,
    _sample,
    _settings_with,
    _settle,
    _views_with,
    aligned_copy,
    block_size,
    new_block,
    njit,
)

__all__: list[str] = []  # private module: the public API is in bank.py


def new_blocks(settings: RelsSettings, n_channels: int) -> np.ndarray:
    """A zeroed (n_channels, stride) array of blocks holding ``settings``, each row
    starting on a 64-byte line (stride: the block size rounded up to a line)."""
    s = settings
    size = block_size(s.na, s.nb, s.nc, s.delay)
    stride = size + (-size % LINE)
    one = np.zeros(stride)
    one[:size] = new_block(settings)
    return aligned_copy(np.tile(one, n_channels)).reshape((n_channels, stride))


#: where a block holds its scales (its settings come first, in RelsSettings order)
U_SCALE = RelsSettings._fields.index("u_scale")
Y_SCALE = RelsSettings._fields.index("y_scale")


@njit(cache=True, error_model="numpy", inline="always", _nrt=False)
def _all_finite(blocks: np.ndarray, rec: np.ndarray, k: int) -> bool:
    """True if every channel's u(k)/u_scale and y(k)/y_scale is finite."""
    for c in range(blocks.shape[0]):
        u = rec[0, k, c] * (1.0 / blocks[c, U_SCALE])
        y = rec[1, k, c] * (1.0 / blocks[c, Y_SCALE])
        if not (np.isfinite(u) and np.isfinite(y)):
            return False
    return True


@njit(cache=True, error_model="numpy", inline="always", _nrt=False)
def _run_bank(blocks: np.ndarray, rec: np.ndarray, settle: bool, na: int, nb: int, nc: int,
              delay: int) -> int:
    """Run every channel's estimator over a (4, N, C) record, sample by sample.

    Parameters
    ----------
    blocks : float64 (C, stride), one estimator block a row (:func:`new_blocks`)
    rec : float64 (4, N, C), C-contiguous
        Rows u(k), y(k) in (each channel's step sees u/u_scale, y/y_scale of its own
        settings); e(k) and ξ̂(k) out, times y_scale, as :func:`._kernels.rels_run`.
    settle : bool
        Apply each channel's last pending (22) at the end (see :func:`._kernels.rels_run`).
    na, nb, nc, delay : int
        The orders, constants of the compiled kernel.

    Returns
    -------
    int
        The number of samples run: N, or k if some channel's u(k) or y(k) (scaled)
        is not finite (no channel runs sample k).
    """
    n_run = 0
    for k in range(rec.shape[1]):
        if not _all_finite(blocks, rec, k):
            break
        for c in range(blocks.shape[0]):
            block = blocks[c]
            s = _settings_with(block, na, nb, nc, delay)
            counters = block[N_SETTINGS:NOISE_VAR]
            st = _views_with(block, na, nb, nc, delay)
            u = rec[0, k, c] * (1.0 / s.u_scale)
            y = rec[1, k, c] * (1.0 / s.y_scale)
            e, xi, pending = _sample(s, block, counters, st, block[PENDING] != 0.0, u, y,
                                     True)
            block[PENDING] = 1.0 if pending else 0.0
            rec[2, k, c] = e * s.y_scale
            rec[3, k, c] = xi * s.y_scale
        n_run += 1
    if settle:
        for c in range(blocks.shape[0]):
            _settle(blocks[c], na, nb, nc, delay, True)
    return n_run


#: the one signature a bank kernel is compiled for
BANK_SIGNATURE = (types.float64[:, ::1], types.float64[:, :, ::1], types.boolean)


def bank_kernel(na: int, nb: int, nc: int, delay: int) -> Any:
    """The compiled bank loop for these orders (an entry point taking
    :data:`BANK_SIGNATURE`'s arguments): compiled on first use, then loaded from
    numba's cache on disk."""
    key = (int(na), int(nb), int(nc), int(delay))
    entry = _BANKS.get(key)
    if entry is None:
        entry = _BANKS[key] = _bank_dispatcher(*key).compile(BANK_SIGNATURE)
    return entry


_BANKS: dict[tuple[int, int, int, int], Any] = {}


def _bank_dispatcher(na_: int, nb_: int, nc_: int, delay_: int) -> Any:
    """A dispatcher of :func:`_run_bank` with the orders fixed."""

    def rels_bank_run(blocks: np.ndarray, rec: np.ndarray, settle: bool) -> int:
        return _run_bank(blocks, rec, settle, na_, nb_, nc_, delay_)

    return njit(cache=True, error_model="numpy", _nrt=False)(rels_bank_run)


def bank_record(u: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The (4, N, C) record of a bank: u, y (each (N, C)), then room for e and ξ̂."""
    rec = np.empty((4,) + u.shape)
    rec[0] = u
    rec[1] = y
    return rec
