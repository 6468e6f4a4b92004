"""Numba kernels of recursive extended least squares (RELS), eqs (19)–(22), and RML.

One loop, :func:`rels_run`, runs the estimator over a record; the streaming estimator
calls the same compiled loop with a record of one sample, and a bank of channels
(:mod:`._bank_kernels`) runs its per-sample step on each channel. So the per-sample
code exists once; it is compiled for any orders (:func:`rels_run`) or for one set of
orders as constants (:func:`specialised`; "Orders: generic and specialised" below).
The kernels do no validation: :mod:`ehss.identification.rels` does.

Two estimators share the loop, selected by ``RelsSettings.rml``:

* RELS (the paper's eqs 19–22): the gain and the P update are driven by ψ̂(k);
* RML: recursive maximum likelihood, i.e. the recursive prediction-error method for
  ARMAX (Ljung & Söderström, *Theory and Practice of Recursive Identification*, MIT
  Press 1983). e(k), θ̂ and ξ̂ use ψ̂(k) as in RELS, but the gain and the P update use
  the gradient of the prediction error, the regressor filtered through 1/Ĉ(q⁻¹):
  ψ_f(k) = ψ̂(k) − ĉ1 ψ_f(k−1) − … − ĉnc ψ_f(k−nc). RELS converges only where
  1/C − 1/2 is strictly positive real; RML does not need that condition, which fails
  for output-error records (C ≈ A with lightly damped roots). With nc = 0 the filter
  is the identity and RML is RELS.

Symbol table (paper → code)
---------------------------
=================  ==========  ==============================================
paper              code        meaning
=================  ==========  ==============================================
θ̂(k)               theta       [a1..a_na, b0..b_nb, c1..c_nc], n entries
ψ̂(k)               psi         [−y(k−1)..−y(k−na), u(k−d)..u(k−d−nb),
                               ξ̂(k−1)..ξ̂(k−nc)]
r(k)               r           regressor of (21)–(22): ψ̂(k) (RELS), ψ_f(k) (RML)
P(k)               P           covariance-like gain matrix, shape (n, n)
P(k−1) r(k)        g           shared by eqs (21) and (22)
λ (printed "r")    lam         forgetting factor
α, α_c             alpha,      P(0) = diag(α … α, α_c … α_c): α for the a- and
                   alpha_c     b-parts, α_c for the c-part (α_c = α is the paper's αI)
ξ̂(k)               xi          a-posteriori residual, eq (19)
ψ_f(k−j)           psi_f[j]    RML: ψ̂ filtered through 1/Ĉ(q⁻¹), j = 0..nc
=================  ==========  ==============================================

The block
---------
An estimator lives in one float64 array, its *block*: the settings (a
:class:`RelsSettings`, fields in order), the counters (indices :data:`COUNT`,
:data:`RESETS`, :data:`C_PROJECTIONS`, :data:`TRACE_SCALINGS`, :data:`SKIPPED`), the
running noise variance, the pending flag (below), then the state arrays, each on a
64-byte line of the line-aligned block (:data:`LINE`). Inside the kernels nothing else
is read by index: :func:`settings_of` gives the settings as a :class:`RelsSettings`
and :func:`views` the state as named arrays (:func:`_starts` is the one definition of
the layout). One array is what makes the streaming call cheap: every argument
crossing the Python → numba boundary costs time to unbox; a streaming sample passes
the block, its own ``io`` as the record, and an empty history.

(22) one sample late
--------------------
P is read twice per sample: by the gain g(k) = P(k−1) r(k) and by the update (22)
that makes P(k). The loop applies the update of sample k−1 at the start of sample k,
in the same pass over P that forms g(k), so that P is read and written once per
sample; between samples it keeps w = g / √(λ den) of the pending update. A batch
run ends by applying the last pending update (``settle``), so that the block then
holds P(k); a streaming sample leaves it pending for the next one (one pass over P
per sample), and readers of P settle it first with a run of no samples.

Safeguards (all kept from the paper's reading in PAPER.md §3)
------------------------------------------------------------
* P is updated in a symmetric rank-1 form, so it stays exactly symmetric;
* with λ < 1 a tiny diagonal floor keeps P positive definite against rounding, and
  tr P is bounded (scaled down to ``trace_max``) against wind-up;
* ψ̂ᵀPψ̂ < 0, a non-positive diagonal entry or a non-finite trace reset P to P(0)
  (θ̂ is kept; RML restarts its filter 1/Ĉ from rest) and count a reset;
* Ĉ(q⁻¹) is kept inside ``c_radius`` (Rouché bound, then an exact Schur–Cohn test;
  roots reflected and shrunk only when it left);
* a step K e that would overflow is skipped and counted.

Compilation
-----------
The kernels allocate nothing (work space is in the block), so they are compiled
without numba's reference counting (``_nrt=False``): arrays are borrowed from the
caller for the duration of a call, and a sample pays no atomic increments and
decrements for the arrays that cross its calls. The per-sample path (:func:`_sample`'s
three parts and the steps they call) is inlined by numba into the loop
(``inline="always"``), with the pass over P at one place only (numba types and
compiles each inlined copy again); the small leaf helpers and the P pass are compiled
once and inlined by LLVM where they are called (``forceinline=True``: a call passes
every array as a struct of seven words, which costs more than the helpers' work, and
hides the constant orders of a specialised loop from the pass; inlining them through
numba instead costs seconds of cold compile, BENCHMARKS.md);
the rare paths (:func:`_gain` of P(0), :func:`_restart`, :func:`_project_c`) stay
calls. What is compiled is kept to what runs: the helpers have no Python entry point
(:data:`HELPER`: numba would otherwise generate and compile a CPython and a C wrapper
for each), and the kernels write ``min``, ``max`` and ``int()`` out as a comparison
and ``np.int64`` (numba compiles each of those built-ins as a function of its own on
first use). No complex arithmetic (slow to compile), no fastmath (measured: no gain).
Literal constants are never passed to a kernel from Python: numba would compile the
callee once more for each literal.

Orders: generic and specialised
-------------------------------
The loop is written once, as the body of a closure (:func:`_entry`) over the orders:
:func:`rels_run`, the generic entry point, reads them from the block;
:func:`specialised` compiles, once per orders and into numba's disk cache, an entry
point that has them as constants (numba's cache keys a closure by the values it
holds), so that LLVM sees every loop bound and offset as a number. (The loop is the
body of the entry point, not a function each entry point inlines: numba would type and
compile the inlined copy again, at a cost in cold compile; BENCHMARKS.md.)
Loop bounds are therefore taken from the orders, never from array shapes (a slice's
length is clamped at run time, which would hide the constant), and P and the RML rows
are flat arrays (numba's ``reshape`` goes through a C helper that hides the row
length). Both run the same operations in the same order: the results are equal bit
for bit. The RML rows are read and shifted through slices of ψ_f, not as
ψ_f[j·n + i]: with a run-time n numba cannot prove such an index non-negative, keeps
its negative-index wrap-around in the loop, and LLVM does not vectorise it (what
that cost: BENCHMARKS.md). :func:`kernel_for` picks one: the
specialised loop once it has been compiled (in this process, or found in the disk
cache), else the generic one; compiling a specialised loop is asked for by
:func:`ehss.identification.rels.specialise_rels`. Each entry point is one
compiled signature (:data:`RELS_RUN_SIGNATURE`), called through the entry point
``Dispatcher.compile`` returns, so that a call does not pay numba's typing.
BENCHMARKS.md has the measurements.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np
from numba import njit as _numba_njit
from numba import types

#: numba's njit (its typing stubs do not list the private ``_nrt`` option used here)
njit: Callable[..., Any] = _numba_njit

__all__: list[str] = []  # private module: the public API is in rels.py

#: options of the helpers that only kernels call: no Python entry point (no CPython or
#: C wrapper to generate and compile; calling one from Python is not possible)
HELPER: dict[str, Any] = {"cache": True, "error_model": "numpy", "_nrt": False,
                          "no_cpython_wrapper": True, "no_cfunc_wrapper": True}

#: δ = EPS_FLOOR · n · tr P is added to P's diagonal after each update when λ < 1
EPS_FLOOR = 8.0 * 2.220446049250313e-16


class RelsSettings(NamedTuple):
    """Orders and scalar settings of one estimator, the first entries of its block."""

    na: int
    nb: int
    nc: int
    delay: int
    lam: float  # λ in (0, 1]
    alpha: float  # α of P(0), a- and b-part
    alpha_c: float  # α_c of P(0), c-part
    trace_max: float  # bound of tr P
    c_radius: float  # roots of Ĉ kept inside this radius
    rml: bool  # True: RML (needs nc > 0), False: RELS
    enabled: bool  # False: θ̂ and P frozen, regressors still run
    u_scale: float = 1.0  # rels_run: u/u_scale is what the step sees
    y_scale: float = 1.0  # y/y_scale likewise; e and ξ̂ come out times y_scale


#: block[SETTINGS] holds the RelsSettings fields in order (booleans as 0.0 / 1.0)
N_SETTINGS = len(RelsSettings._fields)
ENABLED = RelsSettings._fields.index("enabled")
#: counters, block[COUNTERS]: indices into that slice
COUNT = 0  # samples processed
RESETS = 1  # P reset to P(0)
C_PROJECTIONS = 2  # Ĉ moved back inside c_radius
TRACE_SCALINGS = 3  # P scaled down to tr P = trace_max
SKIPPED = 4  # samples that did not update θ̂ (frozen, non-finite or overflowing step)
COUNTER_NAMES = ("n_samples", "resets", "c_projections", "trace_scalings", "skipped")
COUNTERS = slice(N_SETTINGS, N_SETTINGS + len(COUNTER_NAMES))
#: block[NOISE_VAR]: running mean of ξ̂²
NOISE_VAR = COUNTERS.stop
#: block[PENDING]: 1.0 while the (22) of the last sample is not applied (see above)
PENDING = NOISE_VAR + 1
#: the state arrays follow the header
HEADER = PENDING + 1


class RelsState(NamedTuple):
    """The estimator's arrays, views into its block (see :func:`views`)."""

    theta: np.ndarray  # θ̂, shape (n,)
    P: np.ndarray  # P, shape (n, n)
    psi: np.ndarray  # ψ̂ of the next sample (u-part filled on its arrival), (n,)
    g: np.ndarray  # P r, (n,)
    w: np.ndarray  # pending (22): P(k) = P(k−1)/λ − w wᵀ, (n,)
    u_line: np.ndarray  # u_line[j] = u(k−j), (delay + nb + 1,)
    c_work: np.ndarray  # work of the C check and projection, (4 (nc + 1),)
    psi_f: np.ndarray  # RML: rows ψ_f(k), ψ_f(k−1)..ψ_f(k−nc), (nc + 1, n)
    io: np.ndarray  # the streaming sample: u, y in; e, ξ̂ out, (4,)


def block_size(na: int, nb: int, nc: int, delay: int) -> int:
    """Length of the float64 block of an estimator with these orders."""
    return _starts.py_func(na + nb + 1 + nc, delay + nb + 1, nc)[-1]


def new_block(settings: RelsSettings) -> np.ndarray:
    """A zeroed block holding ``settings`` (θ̂ = 0, P = 0: the caller sets P(0)).

    The block starts on a 64-byte line, so that its state arrays do (see LINE); a copy
    of it that does not (``np.copy``) only runs slower: :func:`aligned_copy` keeps it.
    """
    s = settings
    block = aligned_copy(np.zeros(block_size(s.na, s.nb, s.nc, s.delay)))
    block[:N_SETTINGS] = [float(v) for v in settings]
    return block


def aligned_copy(block: np.ndarray) -> np.ndarray:
    """A copy of ``block`` that starts on a 64-byte line, as :func:`new_block`'s do."""
    raw = np.empty(block.size + LINE - 1)
    skip = (-raw.ctypes.data % (8 * LINE)) // 8
    copy = raw[skip : skip + block.size]
    copy[:] = block
    return copy


def set_enabled(block: np.ndarray, enabled: bool) -> None:
    """Freeze (False) or resume (True) adaptation of the estimator in ``block``."""
    block[ENABLED] = 1.0 if enabled else 0.0


def state_views(block: np.ndarray) -> RelsState:
    """The named state arrays of ``block`` (views: writing them writes the block).

    Runs :func:`_views_at` and :func:`_starts` as the plain Python functions they are
    written as (numpy slicing gives the same views), so that the layout is defined
    once and nothing is compiled for Python callers.
    """
    na, nb, nc, delay = (int(v) for v in block[:4])
    n, nu = na + nb + 1 + nc, delay + nb + 1
    st = RelsState(*_views_at.py_func(block, _starts.py_func(n, nu, nc), n, nu, nc))
    return st._replace(P=st.P.reshape((n, n)), psi_f=st.psi_f.reshape((nc + 1, n)))


@njit(cache=True, error_model="numpy", inline="always", _nrt=False)
def settings_of(block: np.ndarray) -> RelsSettings:
    """The :class:`RelsSettings` stored at the start of ``block``."""
    return _settings_with(block, int(block[0]), int(block[1]), int(block[2]),
                          int(block[3]))


@njit(cache=True, error_model="numpy", inline="always", _nrt=False)
def _settings_with(block: np.ndarray, na: int, nb: int, nc: int,
                   delay: int) -> RelsSettings:
    """The settings of ``block`` with these orders: those of the block (generic kernel)
    or compile-time constants equal to them (a kernel specialised to its orders)."""
    return RelsSettings(na, nb, nc, delay,
                        block[4], block[5], block[6], block[7], block[8],
                        block[9] != 0.0, block[10] != 0.0, block[11], block[12])


#: every state array starts on a 64-byte line (8 float64) of a line-aligned block
#: (:func:`new_block`): a vector store to g that straddles two lines is not forwarded
#: to the next row's load of g in the P pass, which then waits for the store to
#: complete (BENCHMARKS.md has the pass timed on and off the line)
LINE = 8


@njit(cache=True, error_model="numpy", inline="always", _nrt=False)
def _starts(n: int, nu: int, nc: int) -> tuple[int, ...]:
    """Where each state array starts in the block, in :class:`RelsState` order, then
    where the block ends: the one definition of the layout (``nu`` = delay + nb + 1).
    Each array starts on the first line at or after the end of the one before
    (o + (−o mod LINE)); P comes after the vectors that the P pass reads and writes."""
    theta = HEADER + (-HEADER % LINE)
    psi = (theta + n) + (-(theta + n) % LINE)
    g = (psi + n) + (-(psi + n) % LINE)
    w = (g + n) + (-(g + n) % LINE)
    u_line = (w + n) + (-(w + n) % LINE)
    c_work = (u_line + nu) + (-(u_line + nu) % LINE)
    psi_f = (c_work + 4 * (nc + 1)) + (-(c_work + 4 * (nc + 1)) % LINE)
    P = (psi_f + (nc + 1) * n) + (-(psi_f + (nc + 1) * n) % LINE)
    io = (P + n * n) + (-(P + n * n) % LINE)
    return theta, P, psi, g, w, u_line, c_work, psi_f, io, io + 4


@njit(cache=True, error_model="numpy", inline="always", _nrt=False)
def views(block: np.ndarray) -> tuple[np.ndarray, ...]:
    """The state arrays of ``block``, in :class:`RelsState` order (see :func:`_starts`),
    P and ψ_f flat (row-major: P[i n + j] is P_ij, psi_f[j n + i] is ψ_f(k−j)_i; the
    Python views, :func:`state_views`, have their two axes)."""
    return _views_with(block, int(block[0]), int(block[1]), int(block[2]), int(block[3]))


@njit(cache=True, error_model="numpy", inline="always", _nrt=False)
def _views_with(block: np.ndarray, na: int, nb: int, nc: int,
                delay: int) -> tuple[np.ndarray, ...]:
    """:func:`views` for these orders (run-time values or compile-time constants: with
    constants every shape below is one, and so is every loop bound taken from it).

    P and ψ_f stay flat: numba's ``reshape`` computes the new shape in a call that
    LLVM cannot see through, which would hide the constant row length."""
    n = na + nb + 1 + nc
    nu = delay + nb + 1
    return _views_at(block, _starts(n, nu, nc), n, nu, nc)


@njit(cache=True, error_model="numpy", inline="always", _nrt=False)
def _views_at(block: np.ndarray, starts: tuple[int, ...], n: int, nu: int,
              nc: int) -> tuple[np.ndarray, ...]:
    """The state arrays of ``block`` that start at ``starts`` (:func:`_starts`)."""
    o_theta, o_P, o_psi, o_g, o_w, o_u, o_c, o_f, o_io, _ = starts
    return (block[o_theta : o_theta + n],
            block[o_P : o_P + n * n],
            block[o_psi : o_psi + n],
            block[o_g : o_g + n],
            block[o_w : o_w + n],
            block[o_u : o_u + nu],
            block[o_c : o_c + 4 * (nc + 1)],
            block[o_f : o_f + (nc + 1) * n],
            block[o_io : o_io + 4])


# ---------------------------------------------------------------- small helpers
@njit(**HELPER, forceinline=True)
def _dot(p: np.ndarray, q: np.ndarray, n: int) -> float:
    """pᵀq, in four partial sums.

    A float sum is one chain of dependent additions that numba may not reorder
    (no fastmath); four interleaved partial sums cut its latency by four. Any
    summation order is as accurate (the tests compare with numpy's own dot).
    """
    s0 = s1 = s2 = s3 = 0.0
    i = 0
    while i + 4 <= n:
        s0 += p[i] * q[i]
        s1 += p[i + 1] * q[i + 1]
        s2 += p[i + 2] * q[i + 2]
        s3 += p[i + 3] * q[i + 3]
        i += 4
    while i < n:
        s0 += p[i] * q[i]
        i += 1
    return (s0 + s1) + (s2 + s3)


@njit(**HELPER, forceinline=True)
def _push_input(u_line: np.ndarray, psi: np.ndarray, u: float, na: int, nb: int,
                delay: int) -> None:
    """u_line[j] = u(k−j); ψ̂'s u-part becomes u(k−d)..u(k−d−nb)."""
    for j in range(delay + nb, 0, -1):
        u_line[j] = u_line[j - 1]
    u_line[0] = u
    for j in range(nb + 1):
        psi[na + j] = u_line[delay + j]


@njit(**HELPER, forceinline=True)
def _filter_regressor(psi_f: np.ndarray, psi: np.ndarray, theta: np.ndarray, o: int,
                      n: int, nc: int) -> None:
    """RML: ψ_f(k) = ψ̂(k) − ĉ1 ψ_f(k−1) − … − ĉnc ψ_f(k−nc), into row 0.

    Ĉ = Ĉ(k−1), kept inside c_radius, so the filter 1/Ĉ is stable. Runs on every
    sample (frozen or skipped ones too) so that its history stays that of the data.
    """
    f0 = psi_f[:n]
    for i in range(n):
        f0[i] = psi[i]
    for j in range(1, nc + 1):
        cj = theta[o + j - 1]
        fj = psi_f[j * n : (j + 1) * n]
        for i in range(n):
            f0[i] -= cj * fj[i]


@njit(**HELPER, forceinline=True)
def _shift_regressors(psi: np.ndarray, psi_f: np.ndarray, n: int, na: int, nc: int,
                      rml: bool, y: float, xi: float) -> None:
    """ψ̂ for k+1: the y-part gets −y(k), the c-part ξ̂(k) (the u-part: _push_input);
    RML: ψ_f(k) becomes ψ_f((k+1)−1) (rows move down by one)."""
    for i in range(na - 1, 0, -1):
        psi[i] = psi[i - 1]
    psi[0] = -y
    o = n - nc
    for i in range(nc - 1, 0, -1):
        psi[o + i] = psi[o + i - 1]
    if nc > 0:
        psi[o] = xi
    if not rml:
        return
    later, earlier = psi_f[n : (nc + 1) * n], psi_f[: nc * n]
    for i in range(nc * n - 1, -1, -1):  # backwards: the two overlap
        later[i] = earlier[i]


# ---------------------------------------------------------------- the C check
@njit(**HELPER, forceinline=True)
def _c_within(theta: np.ndarray, o: int, nc: int, radius: float, cw: np.ndarray) -> bool:
    """True if all roots of z^nc + c1 z^(nc−1) + … + c_nc lie strictly inside ``radius``.

    The coefficients are theta[o:o+nc]. Cheap sufficient test first (Rouché:
    Σ|c_i| r^−i < 1 ⇒ inside), then the exact Schur–Cohn step-down (reflection
    coefficients |k_m| < 1) on q_i = c_i r^−i, O(nc²) and allocation free; ``cw`` is
    work (nc + 1).
    """
    s = 0.0
    rp = 1.0
    inv_r = 1.0 / radius
    for i in range(nc):
        rp *= inv_r
        cw[i + 1] = theta[o + i] * rp
        s += abs(cw[i + 1])
    if s < 1.0:
        return True
    if not np.isfinite(s):
        return False
    # Schur–Cohn / Levinson step-down of the monic polynomial [1, q1..qm]:
    # q_i ← (q_i − k q_{m−i}) / (1 − k²), i = 1..m−1, in place (pairwise)
    for m in range(nc, 0, -1):
        k = cw[m]
        if abs(k) >= 1.0:
            return False
        den = 1.0 - k * k
        i = 1
        j = m - 1
        while i <= j:
            qi = cw[i]
            qj = cw[j]
            cw[i] = (qi - k * qj) / den
            cw[j] = (qj - k * qi) / den
            i += 1
            j -= 1
    return True


@njit(**HELPER)
def _poly_roots(c: np.ndarray, re: np.ndarray, im: np.ndarray) -> None:
    """Roots of z^nc + c1 z^(nc−1) + … + c_nc, as re + j im, by the Weierstrass
    (Durand–Kerner) iteration z_i ← z_i − C(z_i) / Π_{j≠i} (z_i − z_j).

    Started on the powers of 0.4 + 0.9j scaled to the Cauchy bound 1 + max|c_j|; it
    converges for any start off the symmetric ones (quadratically to simple roots,
    linearly to multiple ones, hence up to 1000 sweeps; nc is small and this runs only
    when Ĉ left the disc). Complex numbers are written as (real, imaginary) pairs.
    """
    nc = c.shape[0]
    bound = 1.0
    for j in range(nc):
        bj = 1.0 + abs(c[j])
        bound = bj if bj > bound else bound  # max(bound, bj)
    zr, zi = bound, 0.0  # bound (0.4 + 0.9j)^i
    for i in range(nc):
        re[i], im[i] = zr, zi
        zr, zi = 0.4 * zr - 0.9 * zi, 0.9 * zr + 0.4 * zi
    for _ in range(1000):
        change = 0.0
        for i in range(nc):
            zr, zi = re[i], im[i]
            pr, pi = 1.0, 0.0  # C(z_i) by Horner
            dr, di = 1.0, 0.0  # Π_{j≠i} (z_i − z_j)
            for j in range(nc):
                pr, pi = pr * zr - pi * zi + c[j], pr * zi + pi * zr
                if j != i:
                    ar, ai = zr - re[j], zi - im[j]
                    dr, di = dr * ar - di * ai, dr * ai + di * ar
            m2 = dr * dr + di * di  # C(z_i) / Π = p d̄ / |d|²
            xr, xi = (pr * dr + pi * di) / m2, (pi * dr - pr * di) / m2
            re[i] = zr - xr
            im[i] = zi - xi
            step = np.sqrt(xr * xr + xi * xi)
            change = step if step > change else change  # max(change, step)
        if not change > 2.220446049250313e-16 * bound:  # converged, or NaN
            break


@njit(**HELPER)
def _project_c(c: np.ndarray, radius: float, work: np.ndarray) -> None:
    """Move the roots of C(z) = z^nc + c1 z^(nc−1) + … inside ``radius``, in place.

    Roots outside the unit circle are reflected (z → 1/z̄, which keeps |C(e^{jω})| up to
    a constant: the spectral factor of the same noise spectrum), then any root still
    beyond ``radius`` is shrunk radially onto it (as MATLAB's recursive estimators do).
    ``work`` has 4 (nc + 1) entries. Runs only when :func:`_c_within` failed.
    """
    nc = c.shape[0]
    re, im = work[:nc], work[nc : 2 * nc]
    pr, pi = work[2 * nc : 3 * nc + 1], work[3 * nc + 1 : 4 * nc + 2]
    # roots of the polynomial scaled to z = σ v, σ = max_j |c_j|^(1/j) ≥ 1, whose
    # coefficients c_j / σ^j are at most 1 in size (no overflow in the iteration)
    sigma = 1.0
    for j in range(nc):
        root = abs(c[j]) ** (1.0 / (j + 1))
        sigma = root if root > sigma else sigma  # max(sigma, root)
    scale = 1.0
    for j in range(nc):
        scale *= sigma  # σ^(j+1)
        c[j] = c[j] / scale
    _poly_roots(c, re, im)
    for i in range(nc):
        zr, zi = re[i] * sigma, im[i] * sigma
        r2 = zr * zr + zi * zi
        if r2 > 1.0:  # 1/z̄ = z / |z|²
            zr, zi = zr / r2, zi / r2
            r2 = 1.0 / r2
        r = np.sqrt(r2)
        if r > radius:
            zr, zi = zr * (radius / r), zi * (radius / r)
        re[i], im[i] = zr, zi
    # rebuild the monic polynomial Π (z − z_i): p_j ← p_j − z_i p_{j−1}
    for j in range(nc + 1):
        pr[j] = 1.0 if j == 0 else 0.0
        pi[j] = 0.0
    for i in range(nc):
        for j in range(i + 1, 0, -1):
            pr[j], pi[j] = (pr[j] - (re[i] * pr[j - 1] - im[i] * pi[j - 1]),
                            pi[j] - (re[i] * pi[j - 1] + im[i] * pr[j - 1]))
    finite = True
    for j in range(nc):
        c[j] = pr[j + 1]
        finite = finite and np.isfinite(c[j])
    for j in range(nc):
        if not finite:  # Ĉ beyond float64 (adversarial data): C = 1
            c[j] = 0.0


# ---------------------------------------------------------------- eqs (21)–(22)
@njit(**HELPER)
def _gain(P: np.ndarray, r: np.ndarray, g: np.ndarray, n: int) -> None:
    """g = P r for symmetric P, as g += P[j, :] r_j (row axpys, which vectorise)."""
    for i in range(n):
        g[i] = 0.0
    for j in range(n):
        rj = r[j]
        for i in range(n):
            g[i] += P[j * n + i] * rj


@njit(**HELPER, forceinline=True)
def _update_P_and_gain(P: np.ndarray, w: np.ndarray, inv_lam: float, r: np.ndarray,
                       g: np.ndarray, n: int) -> tuple[float, float]:
    """(22) P(k−1) = P(k−2)/λ − w wᵀ and, in the same pass, g = P(k−1) r(k).

    Returns (tr P, min P_ii) for the guards of :func:`_bring_P_up_to_date`.

    Textbook: P(k) = [I − K rᵀ] P(k−1) / λ, NOT used: rounding makes it drift from
    symmetry and, with λ < 1, diverge. Since K rᵀ P = g gᵀ / den for symmetric P,
    the symmetric rank-1 form P(k) = (P(k−1) − g gᵀ / den) / λ is used, each entry as
    P_ij / λ − w_i w_j with w = g √(1/(den λ)): the same expression for entries (i, j)
    and (j, i), so P stays exactly symmetric. Each new row i is added, times r_i,
    into g (g = Σ_i P[i, :] r_i for symmetric P), so P is read once for both.

    Rows go four at a time, g_j += (p_0j r_0 + p_1j r_1) + (p_2j r_2 + p_3j r_3): g is
    loaded and stored once per four rows, so the chain of additions into g that runs
    through the rows is four times shorter, and the loop over j is long enough that
    LLVM vectorises it rather than unrolling it into scalar code (which it does to a
    one-row loop whose length is a compile-time constant: :func:`specialised`).
    """
    for j in range(n):
        g[j] = 0.0
    i = 0
    while i + 4 <= n:
        o0, o1, o2, o3 = i * n, (i + 1) * n, (i + 2) * n, (i + 3) * n
        w0, w1, w2, w3 = w[i], w[i + 1], w[i + 2], w[i + 3]
        r0, r1, r2, r3 = r[i], r[i + 1], r[i + 2], r[i + 3]
        for j in range(n):
            # P_ij ← P_ij / λ − w_i w_j, rows i..i+3
            p0 = P[o0 + j] * inv_lam - w0 * w[j]
            p1 = P[o1 + j] * inv_lam - w1 * w[j]
            p2 = P[o2 + j] * inv_lam - w2 * w[j]
            p3 = P[o3 + j] * inv_lam - w3 * w[j]
            P[o0 + j] = p0
            P[o1 + j] = p1
            P[o2 + j] = p2
            P[o3 + j] = p3
            g[j] += (p0 * r0 + p1 * r1) + (p2 * r2 + p3 * r3)
        i += 4
    while i < n:  # the last n mod 4 rows, one by one
        wi = w[i]
        ri = r[i]
        for j in range(n):
            p = P[i * n + j] * inv_lam - wi * w[j]
            P[i * n + j] = p
            g[j] += p * ri
        i += 1
    tr = 0.0
    dmin = np.inf
    for i in range(n):
        tr += P[i * n + i]
        pii = P[i * n + i]
        dmin = pii if pii < dmin else dmin  # min(dmin, P_ii)
    return tr, dmin


@njit(**HELPER)
def _restart(s: RelsSettings, counters: np.ndarray, P: np.ndarray, psi_f: np.ndarray,
             psi: np.ndarray, theta: np.ndarray, r: np.ndarray, g: np.ndarray) -> None:
    """P = P(0) = diag(α (a- and b-part), α_c (c-part)), counted as a reset, and
    g = P(0) r. RML: the filter 1/Ĉ restarts from rest (ψ_f history zeroed), so
    r = ψ_f(k) = ψ̂(k). Rare (a guard failed), hence not inlined."""
    nab = s.na + s.nb + 1
    n = nab + s.nc
    counters[RESETS] += 1
    for i in range(n):
        for j in range(n):
            P[i * n + j] = 0.0
        P[i * n + i] = s.alpha if i < nab else s.alpha_c
    if s.rml:
        for j in range(n, (s.nc + 1) * n):
            psi_f[j] = 0.0
        _filter_regressor(psi_f, psi, theta, nab, n, s.nc)
    _gain(P, r, g, n)


@njit(cache=True, error_model="numpy", inline="always", _nrt=False)
def _bring_P_up_to_date(s: RelsSettings, counters: np.ndarray, P: np.ndarray,
                        w: np.ndarray, r: np.ndarray, g: np.ndarray, psi_f: np.ndarray,
                        psi: np.ndarray, theta: np.ndarray, pending: bool,
                        fixed: bool) -> None:
    """Apply the pending (22), if any, with its guards, and form g = P(k−1) r(k).

    Guards after (22): with λ < 1, the diagonal floor δ = 8 n eps tr P: the rank-1
    downdate cancels, its rounding error is about n eps ‖P‖, and with forgetting and
    poor excitation the excited direction of P shrinks to ~(1−λ)/|r|² while the
    others grow, so that error could make the small eigenvalue negative; next to the
    forgetting δ is negligible. (At λ = 1 P only shrinks and rounding stays benign; a
    floor proportional to the large early tr P would act like process noise and bias
    the least-squares limit, so none.) A non-positive diagonal entry or a non-finite
    trace resets P = P(0), as if at the end of the previous sample (RML: ψ_f(k) is
    filtered again from rest, = ψ̂(k)); a trace above trace_max (wind-up under poor
    excitation, P growing like λ^−k in unexcited directions) scales P down to it.
    g follows each change of P: (P + δ I) r = g + δ r, (f P) r = f g.
    """
    n = s.na + s.nb + 1 + s.nc
    if not pending:
        _gain(P, r, g, n)
        return
    if fixed and s.lam == 1.0:  # P_ij · 1 is P_ij: a copy of the pass without the
        tr, dmin = _update_P_and_gain(P, w, 1.0, r, g, n)  # multiply (specialised)
    else:
        tr, dmin = _update_P_and_gain(P, w, 1.0 / s.lam, r, g, n)
    if s.lam < 1.0:
        delta = EPS_FLOOR * n * tr
        for i in range(n):
            P[i * n + i] += delta
            g[i] += delta * r[i]
        tr += n * delta
    if not (dmin > 0.0 and np.isfinite(tr)):
        _restart(s, counters, P, psi_f, psi, theta, r, g)
    elif tr > s.trace_max:
        counters[TRACE_SCALINGS] += 1
        f = s.trace_max / tr
        for i in range(n):
            g[i] *= f
        for i in range(n * n):
            P[i] *= f


@njit(cache=True, error_model="numpy", inline="always", _nrt=False)
def _denominator(s: RelsSettings, counters: np.ndarray, P: np.ndarray, r: np.ndarray,
                 g: np.ndarray, psi_f: np.ndarray, psi: np.ndarray,
                 theta: np.ndarray) -> float:
    """den = λ + rᵀ P(k−1) r of eq (21), with the definiteness guard; g = P(k−1) r.

    rᵀPr ≥ 0 whenever P is positive semi-definite; rᵀPr < 0 proves that P lost
    definiteness through rounding (a tiny positive den would then give a huge gain).
    That, or overflow, resets P = P(0) (RML: and restarts the filter 1/Ĉ, so that
    r = ψ_f(k) = ψ̂(k)) before g and den are formed again.
    """
    n = s.na + s.nb + 1 + s.nc
    q = _dot(r, g, n)
    den = s.lam + q
    if q >= 0.0 and np.isfinite(den):
        return den
    _restart(s, counters, P, psi_f, psi, theta, r, g)
    return s.lam + _dot(r, g, n)


@njit(cache=True, error_model="numpy", inline="always", _nrt=False)
def _update_theta(s: RelsSettings, counters: np.ndarray, theta: np.ndarray, g: np.ndarray,
                  w: np.ndarray, psi: np.ndarray, c_work: np.ndarray, y: float, e: float,
                  den: float) -> tuple[bool, float]:
    """(20)–(21) and (19), and the w of the sample's pending (22); returns (moved,
    ξ̂(k)), moved False if the step K e would overflow (then nothing changed).

    The overflow bound: for positive semi-definite P, |g_i| = |e_iᵀ P r| ≤
    √(P_ii · rᵀPr) ≤ √(tr P · (den − λ)) (Cauchy–Schwarz), and tr P never exceeds
    t_max = max(trace_max, tr P(0)) (P starts or restarts at P(0), and the trace
    bound scales it down), so |K e| ≤ √(t_max (den − λ)) |e| / den: a scalar bound,
    no pass over g. Ĉ is kept inside c_radius (it reads θ̂ only, so it may precede
    (22)), else the ξ̂ feedback of the c-part can blow up.
    """
    inv_den = 1.0 / den
    nab = s.na + s.nb + 1
    tr0 = nab * s.alpha + s.nc * s.alpha_c  # tr P(0)
    t_max = tr0 if tr0 > s.trace_max else s.trace_max  # max(trace_max, tr P(0))
    if not np.isfinite(np.sqrt(t_max * (den - s.lam)) * (abs(e) * inv_den)):
        return False, e
    # (21) K = P ψ̂ / (λ + ψ̂ᵀ P ψ̂);  (20) θ̂(k) = θ̂(k−1) + K e
    # (RML: K = P ψ_f / (λ + ψ_fᵀ P ψ_f), e still with ψ̂)
    step = e * inv_den
    # (22), applied at the next sample: P(k) = P(k−1)/λ − w wᵀ, w = g / √(den λ)
    root = 1.0 / np.sqrt(den * s.lam)
    for i in range(nab + s.nc):
        theta[i] += g[i] * step
        w[i] = g[i] * root
    if s.nc > 0 and not _c_within(theta, nab, s.nc, s.c_radius, c_work):
        _project_c(theta[nab:], s.c_radius, c_work)
        counters[C_PROJECTIONS] += 1
        # (19) ξ̂(k) = y(k) − ψ̂ᵀ(k) θ̂(k), formed directly since the projection moved θ̂
        return True, y - _dot(psi, theta, nab + s.nc)
    # (19) ξ̂(k) = y(k) − ψ̂ᵀ(k) θ̂(k) = e − (ψ̂ᵀ g / den) e, since θ̂ moved by g e/den;
    # for RELS ψ̂ᵀg = ψ̂ᵀPψ̂ = den − λ, so ξ̂ = e λ/den (no second dot product)
    if s.rml:
        return True, e - _dot(psi, g, nab + s.nc) * step
    return True, e * (s.lam * inv_den)


# ---------------------------------------------------------------- one sample
@njit(cache=True, error_model="numpy", inline="always", _nrt=False)
def _sample(s: RelsSettings, block: np.ndarray, counters: np.ndarray,
            st: tuple[np.ndarray, ...], pending: bool, u: float, y: float,
            fixed: bool) -> tuple[float, float, bool]:
    """One RELS or RML sample with every safeguard; returns (e(k), ξ̂(k), pending).

    ``u``, ``y`` are scaled and finite (checked by the callers). e(k) = y(k) −
    ψ̂ᵀ(k)θ̂(k−1) is the a-priori error (0 if it overflows); ξ̂(k) is eq (19)
    (0 if it overflows); ``pending``: θ̂ moved, and w holds its (22). Its three
    parts: :func:`_open_sample`, the pass over P that applies the (22) of the sample
    before (:func:`_bring_P_up_to_date`), :func:`_close_sample`.
    """
    theta, P, psi, g, w, u_line, c_work, psi_f, io = st
    e = _open_sample(s, counters, st, u, y)
    r = psi_f[: s.na + s.nb + 1 + s.nc] if s.rml else psi
    _bring_P_up_to_date(s, counters, P, w, r, g, psi_f, psi, theta, pending, fixed)
    return _close_sample(s, block, counters, st, r, e, y)


@njit(cache=True, error_model="numpy", inline="always", _nrt=False)
def _open_sample(s: RelsSettings, counters: np.ndarray, st: tuple[np.ndarray, ...],
                 u: float, y: float) -> float:
    """A sample up to its pass over P: ψ̂(k) takes u(k), RML filters it into ψ_f(k)
    (the r of that pass); returns the a-priori error e(k)."""
    theta, P, psi, g, w, u_line, c_work, psi_f, io = st
    _push_input(u_line, psi, u, s.na, s.nb, s.delay)
    # ŷ(k|k−1) = ψ̂ᵀ(k) θ̂(k−1);  e(k) = y(k) − ŷ  (the bracket of eq 20)
    n = s.na + s.nb + 1 + s.nc
    e = y - _dot(psi, theta, n)
    counters[COUNT] += 1
    # r, the regressor of the gain and of (22): ψ̂(k) (RELS) or ψ_f(k) (RML)
    if s.rml:
        _filter_regressor(psi_f, psi, theta, s.na + s.nb + 1, n, s.nc)
    return e


@njit(cache=True, error_model="numpy", inline="always", _nrt=False)
def _close_sample(s: RelsSettings, block: np.ndarray, counters: np.ndarray,
                  st: tuple[np.ndarray, ...], r: np.ndarray, e: float,
                  y: float) -> tuple[float, float, bool]:
    """A sample after its pass over P (g = P(k−1) r(k)): (19)–(21), the noise
    variance, and ψ̂ shifted for k+1; returns (e(k), ξ̂(k), pending) as :func:`_sample`.
    """
    theta, P, psi, g, w, u_line, c_work, psi_f, io = st
    moved = False
    xi = e  # ξ̂(k) = e(k) whenever θ̂ is not updated (frozen or skipped)
    if s.enabled and np.isfinite(e):
        den = _denominator(s, counters, P, r, g, psi_f, psi, theta)
        if den > 0.0 and np.isfinite(den):
            moved, xi = _update_theta(s, counters, theta, g, w, psi, c_work, y, e, den)
    if s.enabled and not moved:
        counters[SKIPPED] += 1
    if not np.isfinite(xi):
        xi = 0.0
    # running mean of ξ̂² over the last min(k, 1/(1−λ)) samples (kept if not finite)
    cnt = counters[COUNT]
    if s.lam < 1.0:
        window = 1.0 / (1.0 - s.lam)
        cnt = window if window < cnt else cnt  # min(k, window)
    nv = block[NOISE_VAR] + (xi * xi - block[NOISE_VAR]) / cnt
    if np.isfinite(nv):
        block[NOISE_VAR] = nv
    _shift_regressors(psi, psi_f, s.na + s.nb + 1 + s.nc, s.na, s.nc, s.rml, y, xi)
    return (e if np.isfinite(e) else 0.0), xi, moved


# ---------------------------------------------------------------- the entry points
def _entry(na_: int, nb_: int, nc_: int, delay_: int, fixed: bool) -> Any:
    """A dispatcher of the loop: the generic kernel (``fixed`` False: the orders are
    read from the block at run time, ``na_`` … ``delay_`` unused) or the one
    specialised to the orders ``na_`` … ``delay_`` (``fixed`` True; :func:`specialised`).

    One source for both, a closure (numba's cache tells closures apart by the values
    they hold). Each order is ``na_ if fixed else np.int64(block[0])``: a choice on a
    constant, which LLVM folds before it optimises the loop, so that in a specialised
    kernel every loop bound is a number. (The loop is the entry point's own body, not
    a function inlined by numba into each entry point: that extra level of inlining
    costs cold compile, BENCHMARKS.md.)
    """

    def rels_run(block: np.ndarray, rec: np.ndarray, hist: np.ndarray, hist_every: int,
                 settle: bool) -> int:
        """Run the estimator in ``block`` over a record, or one streaming sample.

        Parameters
        ----------
        block : float64 block of an estimator (:func:`new_block`), updated in place
        rec : float64 (4, N), C-contiguous
            Rows u(k) and y(k) in; the step sees u/u_scale and y/y_scale (the
            settings' scales). Rows e(k), the a-priori prediction error, and ξ̂(k), the
            residual of eq (19), out, times y_scale. The streaming estimator passes its
            block's own ``io`` as a (4, 1) record.
        hist : float64 (N // hist_every, n) out, θ̂ every ``hist_every`` samples
            (row r holds θ̂ after sample (r+1)·hist_every − 1); shape (0, n) for none
        hist_every : int ≥ 1
        settle : bool
            Apply the last sample's pending (22) at the end, so that the block holds
            P(k) (True for every caller but the streaming step; a run of no samples
            with ``settle`` only does that).

        Returns
        -------
        int
            The number of samples run: N, or k if u(k)/u_scale or y(k)/y_scale is not
            finite (the run stops before sample k; the callers check the records, so
            this only happens for a streaming sample or a scale that overflows).
        """
        na = na_ if fixed else np.int64(block[0])
        nb = nb_ if fixed else np.int64(block[1])
        nc = nc_ if fixed else np.int64(block[2])
        delay = delay_ if fixed else np.int64(block[3])
        s = _settings_with(block, na, nb, nc, delay)
        counters = block[N_SETTINGS:NOISE_VAR]
        st = _views_with(block, na, nb, nc, delay)
        theta, P, psi, g, w, u_line, c_work, psi_f, io = st
        inv_us, inv_ys = 1.0 / s.u_scale, 1.0 / s.y_scale
        # (22) of the previous sample not yet applied (w holds it)
        pending = block[PENDING] != 0.0
        # r, the regressor of the gain and of (22): ψ̂(k) (RELS) or ψ_f(k) (RML)
        r = psi_f[: na + nb + 1 + nc] if s.rml else psi
        countdown = hist_every
        row = 0
        n_run = 0
        u = y = e = 0.0
        # _sample's three parts, so that the pass over P is written once in the loop:
        # the run ends at k = N or before a sample that is not finite, where with
        # ``settle`` the pass applies the last pending (22) only (the block then
        # holds P(k))
        for k in range(rec.shape[1] + 1):
            end = k == rec.shape[1]
            if not end:
                u, y = rec[0, k] * inv_us, rec[1, k] * inv_ys
                end = not (np.isfinite(u) and np.isfinite(y))
            if end and not (settle and pending):
                break
            if not end:
                e = _open_sample(s, counters, st, u, y)
            _bring_P_up_to_date(s, counters, P, w, r, g, psi_f, psi, theta, pending, fixed)
            if end:
                pending = False
                break
            e, xi, pending = _close_sample(s, block, counters, st, r, e, y)
            rec[2, k] = e * s.y_scale
            rec[3, k] = xi * s.y_scale
            n_run += 1
            countdown -= 1
            if countdown == 0:
                countdown = hist_every
                if row < hist.shape[0]:
                    for i in range(hist.shape[1]):
                        hist[row, i] = theta[i]
                    row += 1
        block[PENDING] = 1.0 if pending else 0.0
        return n_run

    return njit(cache=True, error_model="numpy", _nrt=False)(rels_run)


#: the generic kernel, for any orders: :func:`_entry`'s ``rels_run``
rels_run = _entry(0, 0, 0, 0, False)


@njit(cache=True, error_model="numpy", inline="always", _nrt=False)
def _settle(block: np.ndarray, na: int, nb: int, nc: int, delay: int, fixed: bool) -> None:
    """Apply the pending (22) of the estimator in ``block``, if any, so that it holds
    P(k) (what :func:`rels_run` does with ``settle``, for a bank's channel)."""
    if block[PENDING] == 0.0:
        return
    s = _settings_with(block, na, nb, nc, delay)
    counters = block[N_SETTINGS:NOISE_VAR]
    theta, P, psi, g, w, u_line, c_work, psi_f, io = _views_with(block, na, nb, nc, delay)
    r = psi_f[: na + nb + 1 + nc] if s.rml else psi
    _bring_P_up_to_date(s, counters, P, w, r, g, psi_f, psi, theta, True, fixed)
    block[PENDING] = 0.0


#: the one signature :func:`rels_run` is compiled for
RELS_RUN_SIGNATURE = (types.float64[::1], types.float64[:, ::1], types.float64[:, ::1],
                      types.int64, types.boolean)


def record(u: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The (4, N) record of :func:`rels_run`: rows u, y, then room for e and ξ̂."""
    rec = np.empty((4, u.shape[0]))
    rec[0] = u
    rec[1] = y
    return rec


def kernel_for(na: int, nb: int, nc: int, delay: int, *,
               compile_now: bool = False) -> Any:
    """The compiled loop to run an estimator with these orders (an entry point taking
    :data:`RELS_RUN_SIGNATURE`'s arguments).

    The one specialised to these orders (:func:`specialised`) when it is compiled in
    this process or found in numba's cache on disk, or when ``compile_now`` asks for
    it; else the generic :func:`rels_run`. Compiling a specialised loop costs as much
    as the generic one (seconds: BENCHMARKS.md) and saves tens of nanoseconds a
    sample, so it is done only when asked for, and then kept on disk for later runs.
    """
    key = (int(na), int(nb), int(nc), int(delay))
    entry = _ENTRIES.get(key)
    if entry is None:
        run = specialised(*key)
        # the disk is looked at once per orders and process
        if not (compile_now or (key not in _NOT_ON_DISK
                                and _cached_on_disk(run, RELS_RUN_SIGNATURE))):
            _NOT_ON_DISK.add(key)
            return rels_run.compile(RELS_RUN_SIGNATURE)
        entry = _ENTRIES[key] = run.compile(RELS_RUN_SIGNATURE)
    return entry


def _cached_on_disk(dispatcher: Any, signature: tuple[Any, ...]) -> bool:
    """True if numba's cache holds ``dispatcher`` compiled for ``signature`` (loading
    it is a matter of milliseconds; numba's loader, used where it is)."""
    try:
        cache = dispatcher._cache  # noqa: SLF001 - numba's own cache of the dispatcher
        return cache.load_overload(types.void(*signature), dispatcher.targetctx) is not None
    except Exception:  # noqa: BLE001 - another numba: treat as not cached
        return False


_ENTRIES: dict = {}
_NOT_ON_DISK: set = set()


def specialised(na: int, nb: int, nc: int, delay: int) -> Any:
    """:func:`rels_run` for these orders, as compile-time constants (a dispatcher).

    The loop is :func:`rels_run`'s again (the same source, :func:`_entry`), with the
    orders as constants instead of the block's values: every loop bound, offset into the block
    and row length is then a constant, which LLVM folds into the addressing and the
    loop control, vectorises without run-time trip counts and, at λ = 1, lets the P
    pass drop its multiply by 1/λ. The results are the generic kernel's, bit for bit
    (the same operations in the same order). Compiled once per orders and kept in
    numba's cache on disk (its index tells closures apart by the values they hold);
    the dispatcher is kept here for the process.
    """
    key = (int(na), int(nb), int(nc), int(delay))
    run = _SPECIALISED.get(key)
    if run is None:
        run = _SPECIALISED[key] = _specialise(*key)
    return run


_SPECIALISED: dict = {}


def _specialise(na: int, nb: int, nc: int, delay: int) -> Any:
    """A new dispatcher of the loop with the orders fixed (see :func:`specialised`)."""
    return _entry(na, nb, nc, delay, True)
