"""Numba kernels of recursive extended least squares (RELS), eqs (19)–(22), and RML.

One step function, :func:`_step`, runs one sample; the streaming estimator calls it
through :func:`rels_update` (one sample per call) and the batch functions through
:func:`rels_run` (a loop over the record). The kernels do no validation:
:mod:`ehss.identification.rels` does.

Two estimators share the step, selected by ``RelsSettings.rml``:

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
P(k)               P           covariance-like gain matrix, shape (n, n)
P(k−1)ψ̂(k)         g           shared by eqs (21) and (22)
λ (printed "r")    lam         forgetting factor
α, α_c             alpha,      P(0) = diag(α … α, α_c … α_c): α for the a- and
                   alpha_c     b-parts, α_c for the c-part (α_c = α is the paper's αI)
ξ̂(k)               xi          a-posteriori residual, eq (19)
ψ_f(k−j)           psi_f[j]    RML: ψ̂ filtered through 1/Ĉ(q⁻¹), j = 0..nc
=================  ==========  ==============================================

State
-----
The settings are a :class:`RelsSettings` (orders and scalars, immutable); the state is
a :class:`RelsState` of named arrays, and the counters an int64 array indexed by
:data:`COUNT`, :data:`RESETS`, :data:`C_PROJECTIONS`, :data:`TRACE_SCALINGS` and
:data:`SKIPPED`. The arrays of a :class:`RelsState` are views into one float64
block (:func:`storage_size`, :func:`state_views`): every argument crossing the
Python → numba boundary costs time to type and unbox (≈ 0.1 µs an array, ≈ 2 µs a
NamedTuple), so the streaming estimator passes three arrays per sample: the block,
the counters and the settings packed in field order (:func:`settings_array`). Inside
the kernels only the named views and the settings' fields are used.

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
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

__all__: list[str] = []  # private module: the public API is in rels.py

#: indices of the int64 counters array
COUNT = 0  # samples processed
RESETS = 1  # P reset to P(0)
C_PROJECTIONS = 2  # Ĉ moved back inside c_radius
TRACE_SCALINGS = 3  # P scaled down to tr P = trace_max
SKIPPED = 4  # samples that did not update θ̂ (frozen, non-finite or overflowing step)
N_COUNTERS = 5
COUNTER_NAMES = ("n_samples", "resets", "c_projections", "trace_scalings", "skipped")

#: δ = EPS_FLOOR · n · tr P is added to P's diagonal after each update when λ < 1
EPS_FLOOR = 8.0 * 2.220446049250313e-16


class RelsSettings(NamedTuple):
    """Orders and scalar settings of one estimator (immutable while it runs)."""

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


class RelsState(NamedTuple):
    """The estimator's arrays (views into one float64 block, see :func:`state_views`)."""

    theta: np.ndarray  # θ̂, shape (n,)
    P: np.ndarray  # P, shape (n, n)
    psi: np.ndarray  # ψ̂ of the next sample (u-part filled on its arrival), (n,)
    g: np.ndarray  # work: P r, (n,)
    u_line: np.ndarray  # u_line[j] = u(k−j), (delay + nb + 1,)
    c_work: np.ndarray  # work of the Schur–Cohn test, (nc + 1,)
    psi_f: np.ndarray  # RML: rows ψ_f(k), ψ_f(k−1)..ψ_f(k−nc), (nc + 1, n)
    noise_var: np.ndarray  # running mean of ξ̂², (1,)


def storage_size(na: int, nb: int, nc: int, delay: int) -> int:
    """Length of the float64 block that holds a :class:`RelsState`."""
    n = na + nb + 1 + nc
    return n + n * n + n + n + (delay + nb + 1) + (nc + 1) + (nc + 1) * n + 1


@njit(cache=True, error_model="numpy")
def state_views(storage, na, nb, nc, delay):
    """The :class:`RelsState` views into ``storage`` (the one definition of the layout)."""
    n = na + nb + 1 + nc
    nu = delay + nb + 1
    o = 0
    theta = storage[o : o + n]
    o += n
    P = storage[o : o + n * n].reshape((n, n))
    o += n * n
    psi = storage[o : o + n]
    o += n
    g = storage[o : o + n]
    o += n
    u_line = storage[o : o + nu]
    o += nu
    c_work = storage[o : o + nc + 1]
    o += nc + 1
    psi_f = storage[o : o + (nc + 1) * n].reshape((nc + 1, n))
    o += (nc + 1) * n
    noise_var = storage[o : o + 1]
    return RelsState(theta, P, psi, g, u_line, c_work, psi_f, noise_var)


# ---------------------------------------------------------------- small helpers
@njit(cache=True, error_model="numpy", inline="always")
def _dot(p, q):
    """pᵀq, in four partial sums.

    A float sum is one chain of dependent additions that numba may not reorder
    (no fastmath); four interleaved partial sums cut its latency by four. Any
    summation order is as accurate (the tests compare with numpy's own dot).
    """
    n = p.shape[0]
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


@njit(cache=True, error_model="numpy")
def _reset_P(P, nab, alpha, alpha_c):
    """P = P(0) = diag(α (first nab entries), α_c (the rest))."""
    n = P.shape[0]
    for i in range(n):
        for j in range(n):
            P[i, j] = 0.0
        P[i, i] = alpha if i < nab else alpha_c


@njit(cache=True, error_model="numpy", inline="always")
def _push_input(u_line, psi, u, na, nb, delay):
    """u_line[j] = u(k−j); ψ̂'s u-part becomes u(k−d)..u(k−d−nb)."""
    for j in range(u_line.shape[0] - 1, 0, -1):
        u_line[j] = u_line[j - 1]
    u_line[0] = u
    for j in range(nb + 1):
        psi[na + j] = u_line[delay + j]


@njit(cache=True, error_model="numpy")
def _filter_regressor(psi_f, psi, theta, o):
    """RML: ψ_f(k) = ψ̂(k) − ĉ1 ψ_f(k−1) − … − ĉnc ψ_f(k−nc), into row 0.

    Ĉ = Ĉ(k−1), kept inside c_radius, so the filter 1/Ĉ is stable. Runs on every
    sample (frozen or skipped ones too) so that its history stays that of the data.
    """
    n = psi.shape[0]
    for i in range(n):
        psi_f[0, i] = psi[i]
    for j in range(1, psi_f.shape[0]):
        cj = theta[o + j - 1]
        for i in range(n):
            psi_f[0, i] -= cj * psi_f[j, i]


@njit(cache=True, error_model="numpy")
def _shift_rows(psi_f):
    """RML: ψ_f(k) becomes ψ_f((k+1)−1): rows move down by one."""
    for j in range(psi_f.shape[0] - 1, 0, -1):
        for i in range(psi_f.shape[1]):
            psi_f[j, i] = psi_f[j - 1, i]


@njit(cache=True, error_model="numpy")
def _clear(a):
    """a = 0 for a 2-D array (RML: the filter 1/Ĉ restarts from rest)."""
    for i in range(a.shape[0]):
        for j in range(a.shape[1]):
            a[i, j] = 0.0


@njit(cache=True, error_model="numpy", inline="always")
def _shift_regressor(psi, na, nc, y, xi):
    """ψ̂ for k+1: the y-part gets −y(k), the c-part ξ̂(k) (the u-part: _push_input)."""
    for i in range(na - 1, 0, -1):
        psi[i] = psi[i - 1]
    psi[0] = -y
    o = psi.shape[0] - nc
    for i in range(nc - 1, 0, -1):
        psi[o + i] = psi[o + i - 1]
    if nc > 0:
        psi[o] = xi


@njit(cache=True, error_model="numpy", inline="always")
def _innovation_variance(nv, xi, count, lam):
    """Running mean of ξ̂² over the last min(k, 1/(1−λ)) samples (kept if not finite)."""
    cnt = float(count)
    if lam < 1.0 and cnt * (1.0 - lam) > 1.0:
        cnt = 1.0 / (1.0 - lam)
    new = nv + (xi * xi - nv) / cnt
    return new if np.isfinite(new) else nv


# ---------------------------------------------------------------- the C check
@njit(cache=True, error_model="numpy", inline="always")
def _c_within(theta, o, nc, radius, cw):
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
    # Schur–Cohn / Levinson step-down of the monic polynomial [1, q1..qm]
    for m in range(nc, 0, -1):
        k = cw[m]
        if abs(k) >= 1.0:
            return False
        _step_down(cw, m, k)
    return True


@njit(cache=True, error_model="numpy")
def _step_down(cw, m, k):
    """q_i ← (q_i − k q_{m−i}) / (1 − k²), i = 1..m−1, in place (pairwise)."""
    den = 1.0 - k * k
    i = 1
    j = m - 1
    while i < j:
        qi = cw[i]
        qj = cw[j]
        cw[i] = (qi - k * qj) / den
        cw[j] = (qj - k * qi) / den
        i += 1
        j -= 1
    if i == j:
        cw[i] = (cw[i] - k * cw[i]) / den


@njit(cache=True, error_model="numpy")
def _horner(c, z):
    """z^nc + c1 z^(nc−1) + … + c_nc at the complex point z."""
    acc = 1.0 + 0.0j
    for j in range(c.shape[0]):
        acc = acc * z + c[j]
    return acc


@njit(cache=True, error_model="numpy")
def _poly_roots(c):
    """Roots of z^nc + c1 z^(nc−1) + … + c_nc by the Weierstrass (Durand–Kerner)
    iteration z_i ← z_i − C(z_i) / Π_{j≠i} (z_i − z_j), started on the powers of
    0.4 + 0.9j scaled to the Cauchy bound 1 + max|c_j|; it converges for any start off
    the symmetric ones (quadratically to simple roots, linearly to multiple ones, hence
    up to 1000 sweeps; nc is small and this runs only when Ĉ left the disc).
    """
    nc = c.shape[0]
    bound = 1.0
    for j in range(nc):
        bound = max(bound, 1.0 + abs(c[j]))
    roots = np.empty(nc, dtype=np.complex128)
    if not np.isfinite(bound):
        roots[:] = np.nan
        return roots
    for i in range(nc):
        roots[i] = bound * (0.4 + 0.9j) ** i
    for _ in range(1000):
        change = 0.0
        for i in range(nc):
            den = 1.0 + 0.0j
            for j in range(nc):
                if j != i:
                    den *= roots[i] - roots[j]
            delta = _horner(c, roots[i]) / den
            roots[i] -= delta
            change = max(change, abs(delta))
        if change <= 2.220446049250313e-16 * bound:
            break
    return roots


@njit(cache=True, error_model="numpy")
def _project_c(c, radius):
    """Move the roots of C(z) = z^nc + c1 z^(nc−1) + … inside ``radius``, in place.

    Roots outside the unit circle are reflected (z → 1/z̄, which keeps |C(e^{jω})| up to
    a constant: the spectral factor of the same noise spectrum), then any root still
    beyond ``radius`` is shrunk radially onto it (as MATLAB's recursive estimators do).
    This allocates, and runs only when :func:`_c_within` failed.
    """
    nc = c.shape[0]
    # roots of the polynomial scaled to z = σ w, σ = max_j |c_j|^(1/j) ≥ 1, whose
    # coefficients c_j / σ^j are at most 1 in size (no overflow in the iteration)
    sigma = 1.0
    for j in range(nc):
        sigma = max(sigma, abs(c[j]) ** (1.0 / (j + 1)))
    scaled = np.empty(nc)
    for j in range(nc):
        scaled[j] = c[j] / sigma ** (j + 1)
    roots = _poly_roots(scaled) * sigma
    for i in range(nc):
        if abs(roots[i]) > 1.0:
            roots[i] = 1.0 / np.conj(roots[i])
        r = abs(roots[i])
        if r > radius:
            roots[i] = roots[i] * (radius / r)
    # rebuild the monic polynomial Π (z − z_i)
    poly = np.zeros(nc + 1, dtype=np.complex128)
    poly[0] = 1.0
    for i in range(nc):
        for j in range(i + 1, 0, -1):
            poly[j] = poly[j] - roots[i] * poly[j - 1]
    for j in range(nc):
        c[j] = poly[j + 1].real
    if not np.all(np.isfinite(c)):  # Ĉ beyond float64 (adversarial data): C = 1
        c[:] = 0.0


# ---------------------------------------------------------------- eqs (20)–(22)
@njit(cache=True, error_model="numpy", inline="always")
def _gain(P, r, g):
    """g = P r for symmetric P, as g += P[j, :] r_j (row axpys, which vectorise)."""
    n = r.shape[0]
    for i in range(n):
        g[i] = 0.0
    for j in range(n):
        rj = r[j]
        for i in range(n):
            g[i] += P[j, i] * rj


@njit(cache=True, error_model="numpy", inline="always")
def _denominator(s, counters, P, g, r, psi_f, psi, theta):
    """g = P(k−1) r and den = λ + rᵀ P(k−1) r of eq (21), with the definiteness guard.

    r is ψ̂(k) (RELS) or ψ_f(k) (RML). rᵀPr ≥ 0 whenever P is positive semi-definite;
    rᵀPr < 0 proves that P lost definiteness through rounding (a tiny positive den
    would then give a huge gain). That, or overflow, resets P = P(0) (RML: and
    restarts the filter 1/Ĉ, so that r = ψ_f(k) = ψ̂(k)) before g and den are formed
    again.
    """
    _gain(P, r, g)
    q = _dot(r, g)
    den = s.lam + q
    if q >= 0.0 and np.isfinite(den):
        return den
    counters[RESETS] += 1
    _reset_P(P, s.na + s.nb + 1, s.alpha, s.alpha_c)
    if s.rml:
        _clear(psi_f)
        _filter_regressor(psi_f, psi, theta, s.na + s.nb + 1)  # ψ_f(k) = ψ̂(k)
    _gain(P, r, g)
    return s.lam + _dot(r, g)


@njit(cache=True, error_model="numpy", inline="always")
def _step_is_safe(s, den, e):
    """True if (20)–(22) may run: den positive and finite, and the step K e finite.

    A huge e with a small den could overflow θ̂. For positive semi-definite P,
    |g_i| = |e_iᵀ P r| ≤ √(P_ii · rᵀPr) ≤ √(tr P · (den − λ)) (Cauchy–Schwarz), and
    tr P never exceeds max(trace_max, tr P(0)) (P starts or restarts at P(0), and
    the trace bound scales it down), so |K e| ≤ √(t_max (den − λ)) |e| / den: a
    scalar bound, no pass over g.
    """
    if not (den > 0.0 and np.isfinite(den)):
        return False
    nab = s.na + s.nb + 1
    t_max = max(s.trace_max, nab * s.alpha + s.nc * s.alpha_c)
    return np.isfinite(np.sqrt(t_max * (den - s.lam)) * (abs(e) / den))


@njit(cache=True, error_model="numpy", inline="always")
def _update_P(s, counters, P, g, psi_f, den):
    """(22) with its guards; P(k) from P(k−1), g = P(k−1) r and den.

    Textbook: P(k) = [I − K rᵀ] P(k−1) / λ, NOT used: rounding makes it drift from
    symmetry and, with λ < 1, diverge. Since K rᵀ P = g gᵀ / den for symmetric P,
    the symmetric rank-1 form P(k) = (P(k−1) − g gᵀ / den) / λ is used, each entry as
    P_ij / λ − w_i w_j with w = g √(1/(den λ)): IEEE products commute, so entries
    (i, j) and (j, i) get identical values and P stays exactly symmetric.

    Then, with λ < 1, the diagonal floor δ = 8 n eps tr P: the rank-1 downdate
    cancels, its rounding error is about n eps ‖P‖, and with forgetting and poor
    excitation the excited direction of P shrinks to ~(1−λ)/|r|² while the others
    grow, so that error could make the small eigenvalue negative; next to the
    forgetting δ is negligible. (At λ = 1 P only shrinks and rounding stays benign; a
    floor proportional to the large early tr P would act like process noise and bias
    the least-squares limit, so none.) A non-positive diagonal entry or a non-finite
    trace resets P = P(0); a trace above trace_max (wind-up under poor excitation,
    P growing like λ^−k in unexcited directions) scales P down to it.
    """
    n = P.shape[0]
    inv_lam = 1.0 / s.lam
    root = np.sqrt(inv_lam / den)
    for i in range(n):
        g[i] *= root  # g becomes w
    tr = 0.0
    dmin = np.inf
    for i in range(n):
        wi = g[i]
        for j in range(n):
            P[i, j] = P[i, j] * inv_lam - wi * g[j]
        tr += P[i, i]
        dmin = min(dmin, P[i, i])
    if s.lam < 1.0:
        delta = EPS_FLOOR * n * tr
        for i in range(n):
            P[i, i] += delta
        tr += n * delta
    if not (dmin > 0.0 and np.isfinite(tr)):
        counters[RESETS] += 1
        _reset_P(P, s.na + s.nb + 1, s.alpha, s.alpha_c)
        if s.rml:
            _clear(psi_f)
    elif tr > s.trace_max:
        counters[TRACE_SCALINGS] += 1
        f = s.trace_max / tr
        for i in range(n):
            for j in range(n):
                P[i, j] *= f


@njit(cache=True, error_model="numpy", inline="always")
def _update_theta(s, counters, theta, g, psi, c_work, y, e, den):
    """(20)–(21) and (19) for an accepted sample; returns ξ̂(k).

    Also keeps Ĉ inside c_radius (it reads θ̂ only, so it may precede (22)), else the
    ξ̂ feedback of the c-part can blow up.
    """
    # (21) K = P ψ̂ / (λ + ψ̂ᵀ P ψ̂);  (20) θ̂(k) = θ̂(k−1) + K e
    # (RML: K = P ψ_f / (λ + ψ_fᵀ P ψ_f), e still with ψ̂)
    inv_den = 1.0 / den
    step = e * inv_den
    for i in range(theta.shape[0]):
        theta[i] += g[i] * step
    if s.nc > 0 and not _c_within(theta, s.na + s.nb + 1, s.nc, s.c_radius, c_work):
        _project_c(theta[s.na + s.nb + 1 :], s.c_radius)
        counters[C_PROJECTIONS] += 1
        # (19) ξ̂(k) = y(k) − ψ̂ᵀ(k) θ̂(k), formed directly since the projection moved θ̂
        return y - _dot(psi, theta)
    # (19) ξ̂(k) = y(k) − ψ̂ᵀ(k) θ̂(k) = e − (ψ̂ᵀ g / den) e, since θ̂ moved by g e/den;
    # for RELS ψ̂ᵀg = ψ̂ᵀPψ̂ = den − λ, so ξ̂ = e λ/den (no second dot product)
    if s.rml:
        return e - _dot(psi, g) * step
    return e * (s.lam * inv_den)


# ---------------------------------------------------------------- one sample
@njit(cache=True, error_model="numpy")
def _step(s, counters, theta, P, psi, g, u_line, c_work, psi_f, noise_var, u, y):
    """One RELS or RML sample with every safeguard; returns (e(k), ξ̂(k)).

    ``u``, ``y`` are scaled and finite (checked by the callers). e(k) = y(k) −
    ψ̂ᵀ(k)θ̂(k−1) is the a-priori error (0 if it overflows); ξ̂(k) is eq (19)
    (0 if it overflows).
    """
    _push_input(u_line, psi, u, s.na, s.nb, s.delay)
    # ŷ(k|k−1) = ψ̂ᵀ(k) θ̂(k−1);  e(k) = y(k) − ŷ  (the bracket of eq 20)
    e = y - _dot(psi, theta)
    counters[COUNT] += 1
    # r, the regressor of the gain and of (22): ψ̂(k) (RELS) or ψ_f(k) (RML)
    if s.rml:
        _filter_regressor(psi_f, psi, theta, s.na + s.nb + 1)
        r = psi_f[0]
    else:
        r = psi
    xi = e  # ξ̂(k) = e(k) whenever θ̂ is not updated (frozen or skipped)
    den = 0.0
    updated = False
    if s.enabled and np.isfinite(e):
        den = _denominator(s, counters, P, g, r, psi_f, psi, theta)
        updated = _step_is_safe(s, den, e)
        if updated:
            xi = _update_theta(s, counters, theta, g, psi, c_work, y, e, den)
        else:
            counters[SKIPPED] += 1
    elif s.enabled:
        counters[SKIPPED] += 1
    if not np.isfinite(xi):
        xi = 0.0
    noise_var[0] = _innovation_variance(noise_var[0], xi, counters[COUNT], s.lam)
    if s.rml:
        _shift_rows(psi_f)
    _shift_regressor(psi, s.na, s.nc, y, xi)
    if updated:
        _update_P(s, counters, P, g, psi_f, den)
    return (e if np.isfinite(e) else 0.0), xi


# ---------------------------------------------------------------- entry points
@njit(cache=True, error_model="numpy")
def rels_run(s, storage, counters, u, y, err, xi_out, hist, hist_every):
    """Run the estimator over a whole record (batch RELS or RML).

    Parameters
    ----------
    s : RelsSettings
    storage : float64 block of a :class:`RelsState`, updated in place
    counters : int64 (N_COUNTERS,), updated in place
    u, y : float64 (N,), scaled, finite
    err : float64 (N,) out, a-priori prediction errors e(k)
    xi_out : float64 (N,) out, a-posteriori residuals ξ̂(k) of eq (19)
    hist : float64 (N // hist_every, n) out, θ̂ every ``hist_every`` samples
        (row r holds θ̂ after sample (r+1)·hist_every − 1); shape (0, n) for none
    hist_every : int ≥ 1
    """
    theta, P, psi, g, u_line, c_work, psi_f, noise_var = state_views(
        storage, s.na, s.nb, s.nc, s.delay
    )
    row = 0
    for k in range(u.shape[0]):
        err[k], xi_out[k] = _step(s, counters, theta, P, psi, g, u_line, c_work, psi_f,
                                  noise_var, u[k], y[k])
        if (k + 1) % hist_every == 0 and row < hist.shape[0]:
            for i in range(hist.shape[1]):
                hist[row, i] = theta[i]
            row += 1


@njit(cache=True, error_model="numpy")
def settings_from_array(a):
    """The :class:`RelsSettings` whose fields, in order, are the entries of ``a``.

    The streaming entry point receives its settings as one float64 array (see the
    module notes); :func:`settings_array` packs them.
    """
    return RelsSettings(int(a[0]), int(a[1]), int(a[2]), int(a[3]), a[4], a[5], a[6],
                        a[7], a[8], a[9] != 0.0, a[10] != 0.0)


def settings_array(settings: RelsSettings) -> np.ndarray:
    """``settings`` as a float64 array, fields in order (read by settings_from_array)."""
    return np.array([float(v) for v in settings])


@njit(cache=True, error_model="numpy")
def rels_update(storage, counters, settings, u, y):
    """Streaming entry point: one sample (scaled); returns the a-priori error e(k).

    ``settings`` is :func:`settings_array` of a :class:`RelsSettings`: one array
    crosses the Python → numba boundary instead of eleven scalars (see the module
    notes). Returns NaN only if ``u`` or ``y`` is not finite, in which case the state
    is left untouched; the Python wrapper turns that into a DataError.
    """
    if not (np.isfinite(u) and np.isfinite(y)):
        return np.nan
    s = settings_from_array(settings)
    theta, P, psi, g, u_line, c_work, psi_f, noise_var = state_views(
        storage, s.na, s.nb, s.nc, s.delay
    )
    return _step(s, counters, theta, P, psi, g, u_line, c_work, psi_f, noise_var, u, y)[0]
