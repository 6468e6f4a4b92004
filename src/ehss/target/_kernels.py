"""The target filter's arithmetic, sample by sample: one definition, run by numba.

Symbols (scipy's ``sos`` layout, direct form II transposed; the C code in
``c/ehss_compensator.c`` does the same operations in the same order):

=========  ===================================================================
``sos``    (MAX_SECTIONS, 6): row ``s`` is ``b0 b1 b2 a0 a1 a2`` (``a0 = 1``)
``z``      (MAX_SECTIONS, 2): the two delay states of each section
``taps``   (MAX_TAPS,): FIR coefficients ``h_0 … h_{n_taps-1}``
``hist``   (MAX_TAPS,): the cascade's last outputs, circular; ``hist[pos]`` newest
=========  ===================================================================
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["filter_block", "crossfade_block"]


@njit(cache=True, error_model="numpy")
def filter_block(sos: np.ndarray, n_sections: int, z: np.ndarray, taps: np.ndarray,
                 n_taps: int, hist: np.ndarray, pos: int, x: np.ndarray,
                 y: np.ndarray) -> int:
    """Run ``x`` through the sections then the FIR part into ``y``; returns the new ``pos``.

    ``z`` and ``hist`` are updated in place. ``filter_block.py_func`` is the same code
    run by the Python interpreter.
    """
    size = hist.shape[0]
    for i in range(x.shape[0]):
        v = x[i]
        for s in range(n_sections):
            # w = b0 v + z0 ;  z0 <- b1 v - a1 w + z1 ;  z1 <- b2 v - a2 w
            w = sos[s, 0] * v + z[s, 0]
            z[s, 0] = sos[s, 1] * v - sos[s, 4] * w + z[s, 1]
            z[s, 1] = sos[s, 2] * v - sos[s, 5] * w
            v = w
        # u = sum_j h_j v[i - j], newest first
        pos += 1
        if pos == size:
            pos = 0
        hist[pos] = v
        acc = 0.0
        j_pos = pos
        for j in range(n_taps):
            acc += taps[j] * hist[j_pos]
            j_pos -= 1
            if j_pos < 0:
                j_pos = size - 1
        y[i] = acc
    return pos


@njit(cache=True, error_model="numpy")
def crossfade_block(y_old: np.ndarray, y_new: np.ndarray, j0: int, n: int) -> None:
    """Blend ``y_new`` into ``y_old`` in place: sample ``i`` is the ``(j0 + i)``-th of a
    cross-fade of ``n`` samples (``1 <= j0 + i <= n``)."""
    for i in range(y_old.shape[0]):
        # w = (k - k0 + 1) / N ;  u = (1 - w) u_old + w u_new
        w = float(j0 + i) / float(n)
        y_old[i] = (1.0 - w) * y_old[i] + w * y_new[i]
