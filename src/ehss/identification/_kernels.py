"""Numba kernels of recursive extended least squares (RELS), eqs (19)–(22), and RML.

Two estimators share one compiled step (:func:`_step`), selected by ``state[H_METHOD]``:

* RELS (method 0, the paper's eqs 19–22): gain and P update driven by ψ̂(k);
* RML (method 1): recursive maximum likelihood, i.e. the recursive prediction-error
  method for ARMAX (Ljung & Söderström, *Theory and Practice of Recursive
  Identification*, MIT Press 1983, RML/RPEM for ARMAX). The prediction error and θ̂
  use ψ̂(k) as in RELS, but the gain and the P update use the gradient of the
  prediction error, the regressor filtered through 1/Ĉ(q⁻¹):
  ψ_f(k) = ψ̂(k) − ĉ1 ψ_f(k−1) − … − ĉnc ψ_f(k−nc). RELS converges only where
  1/C − 1/2 is strictly positive real; RML does not need that condition, which fails
  for output-error records (C ≈ A with lightly damped roots).

The whole estimator state lives in **one** contiguous float64 buffer so that the
streaming wrapper pays the Python→numba dispatch cost for a single array per sample.
The streaming step and the RML batch run :func:`_step`; the RELS batch runs the same
sequence of operations in :func:`_rels_batch` (counters in locals, next gain fused
into the P update), held to the same bits by the tests. The kernels do no validation;
:mod:`ehss.identification.rels` does.

Symbol table (paper → code)
---------------------------
=================  ==========  ==============================================
paper              code        meaning
=================  ==========  ==============================================
θ̂(k)               theta       [a1..a_na, b0..b_nb, c1..c_nc]
ψ̂(k)               psi         [−y(k−1)..−y(k−na), u(k−d)..u(k−d−nb),
                               ξ̂(k−1)..ξ̂(k−nc)]
P(k)               P           covariance-like gain matrix, shape (n, n)
P(k−1)ψ̂(k)         g           shared by eqs (21) and (22)
λ (printed "r")    lam         forgetting factor
α                  alpha       P(0) = diag(α … α, α_c … α_c): α for the a- and
                   alpha_c     b-parts, α_c for the c-part (α_c = α is the paper's αI)
ξ̂(k)               xi          a-posteriori residual, eq (19)
ψ_f(k)             hf[0]       RML: ψ̂(k) filtered through 1/Ĉ(q⁻¹) (L&S 1983)
ψ_f(k−j)           hf[j]       RML: its history, j = 1..nc
=================  ==========  ==============================================

State buffer layout (``state``, float64)::

    [0:HEADER]            header (orders, settings, counters; see the H_* indices)
    theta                 m
    P                     m*m (row major)
    psi                   m   (regressor of the *next* sample, u-part filled on entry)
    g                     m   (work: P psi)
    ul                    d+nb+1 (u delay line, ul[j] = u(k−j))
    cw                    nc+1 (work: Schur–Cohn test of C)
    hf                    (nc+1)*m (RML: rows ψ_f(k), ψ_f(k−1)..ψ_f(k−nc); unused by RELS)

with n = na + nb + 1 + nc and m = n rounded up to a multiple of 4. The padding rows,
columns and entries are zero and stay zero (every update multiplies them by a zero
of ψ̂ or g), so they change no result — adding 0.0 is exact — but every row is a whole
number of 4-wide SIMD vectors and the row loops need no scalar remainder.

The P update (22) is the symmetric rank-1 form P ← (P − g gᵀ/den)/λ with g = P ψ̂,
den = λ + ψ̂ᵀPψ̂, formed as P·(1/λ) − w wᵀ with w = g·√(1/(den·λ)) (one multiply per
entry fewer, exactly symmetric), run by 4-wide kernels in :mod:`._simd` with the sums
ŷ = ψ̂ᵀθ̂, ψ̂ᵀg and tr P in short pairwise trees; beyond SIMD_MAX by plain loops with
the same updates and serial sums. Batch fusion: the batch loop knows u(k+1), so for
RELS at λ = 1 the pass that writes P(k) also forms the next sample's g = P(k) ψ̂(k+1)
in vector registers (same sums, same order, same bits as forming it at the start of
the next sample); P is then read once per sample instead of twice. The streaming step,
RML and λ < 1 (whose diagonal floor changes P after the pass) form g at the start of
each sample.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ehss.identification._simd import SIMD_MAX, downdate, downdate_gain, gain, gain_sums

__all__: list[str] = []  # private module: the public API is in rels.py

# header indices
H_NA = 0
H_NB = 1
H_NC = 2
H_DELAY = 3
H_LAM = 4
H_ALPHA = 5
H_TRMAX = 6
H_CRADIUS = 7
H_ENABLED = 8
H_COUNT = 9
H_RESETS = 10
H_CPROJ = 11
H_TRSCALE = 12
H_SKIPPED = 13
H_XI = 14
H_NV = 15
H_ALPHA_C = 16
H_METHOD = 17
HEADER = 20

#: values of ``state[H_METHOD]``
METHOD_RELS = 0.0
METHOD_RML = 1.0

#: δ = EPS_FLOOR · n · tr P is added to P's diagonal after each update (8 · eps)
EPS_FLOOR = 8.0 * 2.220446049250313e-16


def padded(n: int) -> int:
    """n rounded up to a multiple of 4 (storage size of θ, ψ, g and P's rows)."""
    return (n + 3) // 4 * 4


def state_size(na: int, nb: int, nc: int, delay: int) -> int:
    """Length of the float64 state buffer for the given orders."""
    m = padded(na + nb + 1 + nc)
    return HEADER + m + m * m + m + m + (delay + nb + 1) + (nc + 1) + (nc + 1) * m


def new_state_buffer(na: int, nb: int, nc: int, delay: int) -> np.ndarray:
    """A zeroed state buffer whose P block starts on a 64-byte boundary.

    P's rows are then whole, aligned 32-byte vectors, and no vector load or store of the
    P update straddles a cache line (measured: 3–9 % of a (6,6,4) sample, depending
    on where the allocator happened to put the buffer). The buffer is a view into a
    slightly larger allocation; a copy works the same, only possibly slower.
    """
    size = state_size(na, nb, nc, delay)
    base = np.zeros(size + 8)
    p_start = HEADER + padded(na + nb + 1 + nc)  # index of P[0, 0]
    skip = (-(base.ctypes.data + 8 * p_start) % 64) // 8
    return base[skip : skip + size]


def state_views(state: np.ndarray) -> tuple[np.ndarray, ...]:
    """(theta, P, psi, g, ul, cw, hf) views into ``state``, padding hidden (Python side)."""
    na, nb, nc, d = (int(state[i]) for i in (H_NA, H_NB, H_NC, H_DELAY))
    n = na + nb + 1 + nc
    m = padded(n)
    o = HEADER
    theta = state[o : o + n]
    o += m
    P = state[o : o + m * m].reshape(m, m)[:n, :n]
    o += m * m
    psi = state[o : o + n]
    o += m
    g = state[o : o + n]
    o += m
    ul = state[o : o + d + nb + 1]
    o += d + nb + 1
    cw = state[o : o + nc + 1]
    o += nc + 1
    hf = state[o : o + (nc + 1) * m].reshape(nc + 1, m)[:, :n]
    return theta, P, psi, g, ul, cw, hf


@njit(cache=True, inline="always")
def _c_within(c, o, nc, radius, cw):
    """True if all roots of z^nc + c1 z^(nc−1) + … + c_nc lie strictly inside ``radius``.

    Cheap sufficient test first (Rouché: Σ|c_i| r^−i < 1 ⇒ stable), then the exact
    Schur–Cohn step-down (reflection coefficients |k_m| < 1) on q_i = c_i r^−i, which is
    O(nc²) and allocation free. The coefficients are c[o:o+nc] (θ̂ and the offset of
    its c-part, so no slice is made per sample); ``cw`` is work (nc+1).
    """
    s = 0.0
    rp = 1.0
    inv_r = 1.0 / radius
    for i in range(nc):
        rp *= inv_r
        cw[i + 1] = c[o + i] * rp
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
        den = 1.0 - k * k
        # q_i <- (q_i − k q_{m−i}) / (1 − k²), i = 1..m−1, done pairwise in place
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
    return True


@njit(cache=True)
def _project_c(c, nc, radius):
    """Move the roots of C(z) = z^nc + c1 z^(nc−1) + … inside ``radius``, in place.

    Roots outside the unit circle are reflected (z → 1/z̄, which keeps |C(e^{jω})| up to
    a constant, the spectral factor of the same noise spectrum), then any root still
    beyond ``radius`` is shrunk radially onto it (as MATLAB's recursive estimators do).
    Uses a complex companion matrix (numba's eigvals does not change domain), so it
    allocates; it only runs when :func:`_c_within` failed.
    """
    for j in range(nc):
        if not np.isfinite(c[j]):
            # cannot happen through _step (it never makes θ̂ non-finite); be safe
            for i in range(nc):
                c[i] = 0.0
            return
    comp = np.zeros((nc, nc), dtype=np.complex128)
    for j in range(nc):
        comp[0, j] = -c[j]
    for i in range(1, nc):
        comp[i, i - 1] = 1.0
    roots = np.linalg.eigvals(comp)
    for i in range(nc):
        r = abs(roots[i])
        if r > 1.0:
            roots[i] = 1.0 / np.conj(roots[i])
            r = abs(roots[i])
        if r > radius:
            roots[i] = roots[i] * (radius / r)
    # rebuild the monic polynomial prod (z − z_i)
    poly = np.zeros(nc + 1, dtype=np.complex128)
    poly[0] = 1.0
    for i in range(nc):
        for j in range(i + 1, 0, -1):
            poly[j] = poly[j] - roots[i] * poly[j - 1]
    for j in range(nc):
        c[j] = poly[j + 1].real


@njit(cache=True)
def _reset_P(P, n, nab, alpha, alpha_c):
    """P = P(0) = diag(α (first nab), α_c (rest)) (eq 22); the padding stays zero."""
    m = P.shape[0]
    for i in range(m):
        for j in range(m):
            P[i, j] = 0.0
    for i in range(n):
        P[i, i] = alpha if i < nab else alpha_c


@njit(cache=True, inline="always")
def _views(state):
    """(theta, P, psi, g, ul, cw) padded views of the state buffer (no copy).

    The RML rows come from :func:`_hf_view`; the RELS batch loop passes P in their
    place (never read), so it carries no extra live array.
    """
    na = int(state[H_NA])
    nb = int(state[H_NB])
    nc = int(state[H_NC])
    d = int(state[H_DELAY])
    m = (na + nb + 1 + nc + 3) // 4 * 4
    nu = d + nb + 1
    o = HEADER
    theta = state[o : o + m]
    o += m
    P = state[o : o + m * m].reshape((m, m))
    o += m * m
    psi = state[o : o + m]
    o += m
    g = state[o : o + m]
    o += m
    ul = state[o : o + nu]
    o += nu
    cw = state[o : o + nc + 1]
    return theta, P, psi, g, ul, cw


@njit(cache=True, inline="always")
def _hf_view(state):
    """RML filtered-regressor rows, shape (nc+1, m), ψ_f(k), ψ_f(k−1)..ψ_f(k−nc)."""
    na = int(state[H_NA])
    nb = int(state[H_NB])
    nc = int(state[H_NC])
    d = int(state[H_DELAY])
    m = (na + nb + 1 + nc + 3) // 4 * 4
    o = HEADER + m + m * m + m + m + (d + nb + 1) + (nc + 1)
    return state[o : o + (nc + 1) * m].reshape((nc + 1, m))


@njit(cache=True, inline="always")
def _clear_rows(hf):
    """Zero the RML filtered-regressor rows (filter 1/Ĉ restarts from rest)."""
    for j in range(hf.shape[0]):
        for i in range(hf.shape[1]):
            hf[j, i] = 0.0


@njit(cache=True, inline="always")
def _push_u(ul, psi, u, na, nb, d):
    """u delay line: ul[j] = u(k−j); ψ's u-part becomes u(k−d)..u(k−d−nb)."""
    for j in range(ul.shape[0] - 1, 0, -1):
        ul[j] = ul[j - 1]
    ul[0] = u
    for j in range(nb + 1):
        psi[na + j] = ul[d + j]


@njit(cache=True, inline="always")
def _gain(P, r, g, n):
    """g = P r for symmetric P (r zero beyond n): g_i = Σ_j P_ij r_j, j = 0..n−1 in order.

    Written as g += P[j, :] r_j (rows of the symmetric P read as columns), so each g_i
    still sums j = 0..n−1 left to right — the rounding of the plain dot product — while
    the inner loop is element-wise over whole 4-wide vectors (P's rows are padded to a
    multiple of 4) and vectorises. A dot-product inner loop is one serial add chain
    that, without fastmath, cannot. Rows j ≥ n would only add P_ji · 0 and are skipped.
    For m ≤ SIMD_MAX the 4-wide intrinsic does the same sums with g in registers.
    """
    m = P.shape[1]
    if m <= SIMD_MAX:
        gain(P, g, r, n)
        return
    for i in range(m):
        g[i] = 0.0
    for j in range(n):
        pj = r[j]
        for i in range(m):
            g[i] += P[j, i] * pj


@njit(cache=True, inline="always")
def _trace_min(P, n):
    """(tr P, smallest diagonal entry), summed i = 0..n−1 left to right."""
    tr = 0.0
    dmin = np.inf
    for i in range(n):
        pii = P[i, i]
        tr += pii
        if pii < dmin:
            dmin = pii
    return tr, dmin


@njit(cache=True, inline="always")
def _downdate(P, g, n, inv_den, inv_lam):
    """(22) in place: P ← (P − g gᵀ·inv_den)·inv_lam; returns (tr P, min P_ii).

    Formed as P·inv_lam − w wᵀ, w = g·√(inv_den·inv_lam) (see :mod:`._simd`): by
    the 4-wide intrinsic for m ≤ SIMD_MAX (trace in its pairwise tree), else by plain
    loops and :func:`_trace_min`. ``g`` is work space afterwards (the plain loops
    scale it to w in place; the callers form the next g from scratch).
    """
    m = P.shape[0]
    if m <= SIMD_MAX:
        return downdate(P, g, n, inv_den, inv_lam)
    root = np.sqrt(inv_den * inv_lam)
    for j in range(m):
        g[j] *= root  # w_j, formed once
    for i in range(n):
        wi = g[i]
        for j in range(m):
            P[i, j] = P[i, j] * inv_lam - wi * g[j]
    return _trace_min(P, n)


@njit(cache=True, inline="always")
def _floor_and_bound(P, n, lam, tr, dmin, trmax):
    """After (22): diagonal floor (λ < 1), definiteness guard, trace bound.

    Returns 0 (P kept), 1 (P must be reset: a non-positive diagonal or a non-finite
    trace) or 2 (P was scaled down to tr P = trmax).

    Floor (λ < 1 only): the rank-1 downdate cancels; its rounding error is about
    n·eps·‖P‖. With forgetting and poor excitation (long constant stretches) the
    unexcited directions of P grow to the trace bound while the excited one shrinks to
    ~(1−λ)/|ψ̂|², and that error makes the small eigenvalue slightly negative.
    δ = 8·n·eps·tr P on the diagonal keeps P positive definite; next to the forgetting
    it is negligible. At λ = 1, P only shrinks, rounding stays benign, and a floor
    proportional to the large early tr P would act like process noise and bias the LS
    limit, so none. Trace bound: with λ < 1 and poor excitation P grows like λ^−k in
    the unexcited directions ("wind-up"); scaling keeps tr P ≤ trmax.
    """
    if lam < 1.0:
        delta = EPS_FLOOR * n * tr
        for i in range(n):
            P[i, i] += delta
        tr += n * delta
    if not (dmin > 0.0 and np.isfinite(tr)):
        return 1
    if tr > trmax:
        f = trmax / tr
        m = P.shape[1]
        for i in range(n):
            for j in range(m):
                P[i, j] *= f
        return 2
    return 0


@njit(cache=True, inline="always")
def _keep_c_stable(theta, o, nc, radius, cw):
    """Project Ĉ(q⁻¹) = 1 + θ̂[o:o+nc] q⁻¹ + … inside ``radius`` if it left; True if moved."""
    if _c_within(theta, o, nc, radius, cw):
        return False
    _project_c(theta[o : o + nc], nc, radius)
    return True


@njit(cache=True, inline="always")
def _shift_regressor(psi, na, nc, o, y, xi):
    """ψ̂ for k+1: the y-part gets −y(k), the c-part ξ̂(k) (the u-part: :func:`_push_u`)."""
    for i in range(na - 1, 0, -1):
        psi[i] = psi[i - 1]
    psi[0] = -y
    for i in range(nc - 1, 0, -1):
        psi[o + i] = psi[o + i - 1]
    if nc > 0:
        psi[o] = xi


@njit(cache=True, inline="always")
def _innovation_variance(nv, xi, count, lam):
    """Running mean of ξ̂² over the last min(k, 1/(1−λ)) samples (kept if not finite)."""
    cnt = count
    if lam < 1.0 and cnt * (1.0 - lam) > 1.0:
        cnt = 1.0 / (1.0 - lam)
    new = nv + (xi * xi - nv) / cnt
    return new if np.isfinite(new) else nv


@njit(cache=True, inline="always")
def _restart(P, r, g, n, nab, alpha, alpha_c):
    """P = P(0) and g = P(0) r (zero beyond n); returns s = rᵀg, summed left to right.

    Run when ψ̂ᵀPψ̂ < 0 proves that P lost definiteness, or on overflow (eq 22 restarts).
    """
    _reset_P(P, n, nab, alpha, alpha_c)
    for i in range(g.shape[0]):
        g[i] = 0.0
    s = 0.0
    for i in range(n):
        g[i] = P[i, i] * r[i]
        s += r[i] * g[i]
    return s


@njit(cache=True, inline="always")
def _max_abs(g, n):
    """max(0, max_i |g_i|) over i < n (NaN never wins)."""
    gmax = 0.0
    for i in range(n):
        if abs(g[i]) > gmax:
            gmax = abs(g[i])
    return gmax


@njit(cache=True, inline="always")
def _step_ok(den, inv_den, gmax, e):
    """True if (20)–(22) may run: den = λ + ψ̂ᵀPψ̂ positive and finite, and the step
    K e finite (a huge e with a small den could overflow θ̂); checked with 1/den, which
    the update needs anyway (one division per sample)."""
    return den > 0.0 and np.isfinite(den) and np.isfinite(gmax * (abs(e) * inv_den))


@njit(cache=True, inline="always")
def _residual(xi, direct, psi, theta, n, y):
    """ξ̂(k) of (19), 0 if not finite.

    ``xi`` is the cheap form (e λ/den for RELS, e otherwise); after a projection of C
    changed θ̂ (``direct``) it is formed directly as y(k) − ψ̂ᵀ(k) θ̂(k).
    """
    if direct:
        acc = 0.0
        for i in range(n):
            acc += psi[i] * theta[i]
        xi = y - acc
    return xi if np.isfinite(xi) else 0.0


@njit(cache=True, inline="always")
def _step(state, theta, P, psi, g, ul, cw, hf, u, y, rml):
    """One RELS or RML sample with the safeguards (streaming, and the RML batch loop).

    RELS: eqs (19)–(22). RML (``rml`` True; the callers pass
    ``state[H_METHOD] == METHOD_RML and nc > 0``, see :func:`_is_rml`): the same
    with ψ_f(k) = ψ̂(k)/Ĉ(q⁻¹) in place of ψ̂(k) in the gain (21) and the P update
    (22) (Ljung & Söderström 1983, RML/RPEM for ARMAX); with nc = 0 the filter is the
    identity and RML is RELS bit for bit. ``u``/``y`` are already scaled and finite
    (checked by the callers). The array arguments are the views returned by
    :func:`_views`. Returns the a-priori error e(k) (0 if it is not finite).

    The RELS batch loop (:func:`_rels_batch`) runs the same sequence of operations
    with its counters in locals and the gain of the next sample fused into the P
    update; a test holds the two to the same bits.
    """
    na = int(state[H_NA])
    nb = int(state[H_NB])
    nc = int(state[H_NC])
    d = int(state[H_DELAY])
    n = na + nb + 1 + nc
    m = P.shape[0]  # padded size, multiple of 4

    _push_u(ul, psi, u, na, nb, d)

    # ŷ(k|k−1) = ψ̂ᵀ(k) θ̂(k−1);  e(k) = y(k) − ŷ  (the bracket of eq 20). RELS with
    # m ≤ SIMD_MAX forms g = P(k−1) ψ̂(k) here too, with ŷ, s = ψ̂ᵀg and max|g_i| in
    # the vector kernel's sum order (the batch loop's, bit for bit)
    vector_sums = not rml and m <= SIMD_MAX and state[H_ENABLED] != 0.0
    s = 0.0
    gmax = 0.0
    if vector_sums:
        yhat, s, gmax = gain_sums(P, g, psi, n, theta)
    else:
        yhat = 0.0
        for i in range(n):
            yhat += psi[i] * theta[i]
    e = y - yhat
    state[H_COUNT] += 1.0
    o = na + nb + 1  # start of the c-part of θ̂ and ψ̂

    # r: the regressor of the gain and of the P update — ψ̂(k) for RELS; for RML
    # (L&S 1983) ψ_f(k) = ψ̂(k) − ĉ1 ψ_f(k−1) − … − ĉnc ψ_f(k−nc), with Ĉ = Ĉ(k−1)
    # kept inside c_radius, so the filter 1/Ĉ is stable. It runs on every sample
    # (also frozen or skipped ones) so that its history stays that of the data.
    if rml:
        r = hf[0]
        for i in range(m):
            r[i] = psi[i]
        for j in range(1, nc + 1):
            cj = theta[o + j - 1]
            for i in range(m):
                r[i] -= cj * hf[j, i]
    else:
        r = psi
    # ξ̂(k) of eq (19); equals e(k) whenever θ̂ is not updated (frozen or skipped)
    xi = e
    xi_direct = False
    update = False
    den = 1.0
    lam = state[H_LAM]

    if state[H_ENABLED] != 0.0 and np.isfinite(e):
        alpha = state[H_ALPHA]
        alpha_c = state[H_ALPHA_C]
        nab = na + nb + 1
        # g = P(k−1) ψ̂(k), shared by (21) and (22);  s = ψ̂ᵀ P ψ̂
        # (RML: g = P(k−1) ψ_f(k), s = ψ_fᵀ P ψ_f; r is ψ_f)
        if not vector_sums:
            _gain(P, r, g, n)
            s = 0.0
            for i in range(n):
                s += r[i] * g[i]
            gmax = _max_abs(g, n)
        # denominator of (21): λ + ψ̂ᵀ P ψ̂ ≥ λ whenever P is positive semi-definite.
        # ψ̂ᵀ P ψ̂ < 0 proves that P lost definiteness through rounding (a tiny positive
        # den would then give a huge gain); that, or overflow, resets P = P(0).
        den = lam + s
        if not (s >= 0.0 and np.isfinite(den)):
            state[H_RESETS] += 1.0
            if rml:
                # RML: the filter 1/Ĉ restarts from rest too, so ψ_f(k) = ψ̂(k)
                _clear_rows(hf)
                for i in range(m):
                    r[i] = psi[i]
            s = _restart(P, r, g, n, nab, alpha, alpha_c)
            den = lam + s
            gmax = _max_abs(g, n)
        inv_den = 1.0 / den
        if _step_ok(den, inv_den, gmax, e):
            update = True
            # (21) K = P ψ̂ / (λ + ψ̂ᵀ P ψ̂);  (20) θ̂(k) = θ̂(k−1) + K e
            # (RML: K = P ψ_f / (λ + ψ_fᵀ P ψ_f); θ̂(k) = θ̂(k−1) + K e, e with ψ̂)
            for i in range(n):
                theta[i] += (g[i] * inv_den) * e
            if rml:
                # (19) for RML: ψ̂ᵀθ̂(k) = ψ̂ᵀθ̂(k−1) + (ψ̂ᵀg/den) e, so
                # ξ̂(k) = e − (ψ̂ᵀg/den) e (ψ̂ᵀg ≠ s since g = P ψ_f; one n-term dot)
                t = 0.0
                for i in range(n):
                    t += psi[i] * g[i]
                xi = e - (t * inv_den) * e
            else:
                # (19) without a second dot product: ψ̂ᵀθ̂(k) = ψ̂ᵀθ̂(k−1) + (s/den) e, so
                # ξ̂(k) = e − (s/den) e = e λ/den (exact algebra; used unless C is
                # projected)
                xi = e * (lam * inv_den)
            # keep C(q⁻¹) stable (inside c_radius), else ξ̂ feedback can blow up
            # (reads θ̂ only, so it may precede the P update of (22))
            if nc > 0 and _keep_c_stable(theta, o, nc, state[H_CRADIUS], cw):
                state[H_CPROJ] += 1.0
                xi_direct = True
        else:
            state[H_SKIPPED] += 1.0
    elif state[H_ENABLED] != 0.0:
        state[H_SKIPPED] += 1.0

    xi = _residual(xi, xi_direct, psi, theta, n, y)
    state[H_XI] = xi
    state[H_NV] = _innovation_variance(state[H_NV], xi, state[H_COUNT], lam)

    if rml:
        # RML: ψ_f(k) becomes ψ_f((k+1)−1): shift the filtered-regressor history
        # (before ψ̂ is shifted: r = ψ_f(k) is row 0)
        for j in range(nc, 0, -1):
            for i in range(m):
                hf[j, i] = hf[j - 1, i]
    _shift_regressor(psi, na, nc, o, y, xi)

    if update:
        # (22) P(k) = [I − K ψ̂ᵀ] P(k−1) / λ  — textbook form, NOT used: rounding makes
        # it drift from symmetry and, with λ < 1, diverge. Since K ψ̂ᵀ P = g gᵀ / den
        # for symmetric P, we use the symmetric rank-1 form
        #     P(k) = (P(k−1) − g gᵀ / den) / λ
        # (RML: the same with g = P ψ_f, i.e. P(k) = [I − K ψ_fᵀ] P(k−1) / λ),
        # each entry as P_ij · inv_lam − w_i w_j with w = g √(inv_den · inv_lam). IEEE
        # products commute, so entries (i, j) and (j, i) get bit-identical values: P
        # stays exactly symmetric by construction. Rows i ≥ n are zero (w_i = 0) and
        # stay so.
        tr, dmin = _downdate(P, g, n, 1.0 / den, 1.0 / lam)
        verdict = _floor_and_bound(P, n, lam, tr, dmin, state[H_TRMAX])
        if verdict == 1:
            # guard: reset P = P(0) and keep θ̂ (RML: and restart the filter 1/Ĉ)
            _reset_P(P, n, na + nb + 1, state[H_ALPHA], state[H_ALPHA_C])
            state[H_RESETS] += 1.0
            if rml:
                _clear_rows(hf)
        elif verdict == 2:
            state[H_TRSCALE] += 1.0
    if not np.isfinite(e):
        e = 0.0
    return e


@njit(cache=True, inline="always")
def _is_rml(state):
    """True if the state selects RML and has a C part (else the step is RELS)."""
    return state[H_METHOD] == METHOD_RML and int(state[H_NC]) > 0


@njit(cache=True, inline="always")
def _save_history(hist, theta, row, n):
    """hist[row] = θ̂ (if the history has that row)."""
    if row < hist.shape[0]:
        for i in range(n):
            hist[row, i] = theta[i]


@njit(cache=True)
def _step_batch(state, u, y, err, xi_out, hist, hist_every):
    """:func:`_step` per sample: the RML batch, and RELS for n > SIMD_MAX."""
    theta, P, psi, g, ul, cw = _views(state)
    hf = _hf_view(state)
    rml = _is_rml(state)
    n = hist.shape[1]
    c = 0
    row = 0
    for k in range(u.shape[0]):
        err[k] = _step(state, theta, P, psi, g, ul, cw, hf, u[k], y[k], rml)
        xi_out[k] = state[H_XI]
        c += 1
        if c == hist_every:
            c = 0
            _save_history(hist, theta, row, n)
            row += 1


@njit(cache=True)
def _rels_batch(state, u, y, err, xi_out, hist, hist_every):
    """The RELS batch loop for n ≤ SIMD_MAX: :func:`_step`'s RELS sequence, made fast.

    The same operations in the same order as :func:`_step` (a test holds the two to the
    same bits), with five batch-only changes:

    1. Header values and counters live in locals (written back at the end), so
       nothing in the loop reloads them after every store to θ̂ or P.
    2. The batch knows u(k+1), so ψ̂(k+1) is complete before P(k) is formed: at λ = 1
       the pass that writes P(k) also forms the next sample's g = P(k) ψ̂(k+1)
       (:func:`._simd.downdate_gain`, the same sums in the same order as :func:`_gain`,
       hence the same bits), and P is read once per sample instead of twice. After a
       reset or a trace scaling, or with λ < 1 (the diagonal floor changes P after the
       pass), g is formed at the start of the next sample as in the streaming step.
    3. ŷ, ψ̂ᵀg and max|g_i| come from the vector kernel that formed g, and tr P and
       min P_ii from the one that updated P (the same kernels as in :func:`_step`).
    4. The loop body is written out instead of calling the small helpers that
       :func:`_step` shares: numba brackets every array an inlined helper receives
       with atomic reference-count updates that its pruning pass cannot remove around
       a loop, and those cost ≈ 15 % of a (6,6,4) sample. The Rouché bound of
       :func:`_c_within` is written out too, so the full Schur–Cohn call (with its
       arrays) only runs when the bound fails.
    5. Once the record covers the u line, ψ̂'s u-part is read from ``u`` itself
       instead of shifting the line every sample; the line is rebuilt at the end.

    Same arguments as :func:`rels_run`.
    """
    theta, P, psi, g, ul, cw = _views(state)
    na = int(state[H_NA])
    nb = int(state[H_NB])
    nc = int(state[H_NC])
    d = int(state[H_DELAY])
    n = na + nb + 1 + nc
    o = na + nb + 1
    m = P.shape[0]
    nu = d + nb + 1
    lam = state[H_LAM]
    inv_lam = 1.0 / lam
    alpha = state[H_ALPHA]
    alpha_c = state[H_ALPHA_C]
    trmax = state[H_TRMAX]
    radius = state[H_CRADIUS]
    inv_r = 1.0 / radius
    enabled = state[H_ENABLED] != 0.0
    # views taken once, so the loop indexes from 0 (no wrap-around arithmetic)
    theta_c = theta[o:n]
    psi_c = psi[o:n]
    psi_u = psi[na:o]
    ul_d = ul[d:]
    # r^−(i+1), i < nc, formed by the same multiplications as in _c_within's bound
    rpow = np.empty(nc)
    rp = 1.0
    for i in range(nc):
        rp *= inv_r
        rpow[i] = rp
    count = state[H_COUNT]
    resets = state[H_RESETS]
    cproj = state[H_CPROJ]
    trscale = state[H_TRSCALE]
    skipped = state[H_SKIPPED]
    nv = state[H_NV]
    xi = state[H_XI]
    N = u.shape[0]
    c = 0
    row = 0
    # (ŷ, s, max|g_i|) of the coming sample, from the vector kernels
    yhat = 0.0
    s = 0.0
    gmax = 0.0
    ready = False  # g holds P(k−1) ψ̂(k) and (yhat, s, gmax) its sums
    if N > 0:
        _push_u(ul, psi, u[0], na, nb, d)
    for k in range(N):
        yk = y[k]
        if not ready:
            if enabled:
                # (21) g = P(k−1) ψ̂(k) as _gain, with ŷ = ψ̂ᵀθ̂ (eq 20), s = ψ̂ᵀg and
                # max|g_i|, as in _step
                yhat, s, gmax = gain_sums(P, g, psi, n, theta)
            else:
                yhat = 0.0
                for i in range(n):
                    yhat += psi[i] * theta[i]
        e = yk - yhat
        count += 1.0
        xi = e
        xi_direct = False
        update = False
        den = 1.0
        if enabled and np.isfinite(e):
            den = lam + s
            if not (s >= 0.0 and np.isfinite(den)):
                resets += 1.0
                s = _restart(P, psi, g, n, o, alpha, alpha_c)
                den = lam + s
                gmax = _max_abs(g, n)  # a helper with an array: fine off the hot path
            inv_den = 1.0 / den
            if _step_ok(den, inv_den, gmax, e):
                update = True
                for i in range(n):  # (20), (21)
                    theta[i] += (g[i] * inv_den) * e
                xi = e * (lam * inv_den)  # (19) as e λ/den
                if nc > 0:
                    # C kept inside the radius: Rouché's bound, then _c_within
                    bound = 0.0
                    for i in range(nc):
                        bound += abs(theta_c[i] * rpow[i])
                    if not bound < 1.0 and not _c_within(theta, o, nc, radius, cw):
                        _project_c(theta[o:n], nc, radius)
                        cproj += 1.0
                        xi_direct = True
            else:
                skipped += 1.0
        elif enabled:
            skipped += 1.0
        # (19) directly after a projection of C; 0 if not finite (as _residual)
        if xi_direct:
            acc = 0.0
            for i in range(n):
                acc += psi[i] * theta[i]
            xi = yk - acc
        if not np.isfinite(xi):
            xi = 0.0
        nv = _innovation_variance(nv, xi, count, lam)
        # ψ̂(k+1): y-part, c-part (as _shift_regressor), u-part (as _push_u)
        for i in range(na - 1, 0, -1):
            psi[i] = psi[i - 1]
        psi[0] = -yk
        for i in range(nc - 1, 0, -1):
            psi_c[i] = psi_c[i - 1]
        if nc > 0:
            psi_c[0] = xi
        fuse = k + 1 < N
        if fuse:
            if k + 1 >= nu - 1:
                # u(k+1−d−j) straight from the record; the u line is rebuilt at the end
                for j in range(nb + 1):
                    psi_u[j] = u[k + 1 - d - j]
            else:  # as _push_u (the line still holds samples from before this record)
                for j in range(nu - 1, 0, -1):
                    ul[j] = ul[j - 1]
                ul[0] = u[k + 1]
                for j in range(nb + 1):
                    psi_u[j] = ul_d[j]
        ready = False
        if update:
            # (22) in the symmetric form, as _downdate (+ the next gain at λ = 1)
            inv_den = 1.0 / den
            if fuse and lam == 1.0:
                # also the next sample's g and sums (θ̂(k) and ψ̂(k+1) are complete),
                # and tr P, min P_ii as _downdate
                yhat, s, gmax, tr, dmin = downdate_gain(P, g, psi, n, inv_den, theta)
                ready = True
            else:
                tr, dmin = downdate(P, g, n, inv_den, inv_lam)
            # as _floor_and_bound
            if lam < 1.0:
                delta = EPS_FLOOR * n * tr
                for i in range(n):
                    P[i, i] += delta
                tr += n * delta
            if not (dmin > 0.0 and np.isfinite(tr)):
                _reset_P(P, n, o, alpha, alpha_c)
                resets += 1.0
                ready = False
            elif tr > trmax:
                f = trmax / tr
                for i in range(n):
                    for j in range(m):
                        P[i, j] *= f
                trscale += 1.0
                ready = False
        if not np.isfinite(e):
            e = 0.0
        err[k] = e
        xi_out[k] = xi
        c += 1
        if c == hist_every:
            c = 0
            if row < hist.shape[0]:
                for i in range(n):
                    hist[row, i] = theta[i]
            row += 1
    if N >= nu:  # the u line that the shifts would have left: ul[j] = u(N−1−j)
        for j in range(nu):
            ul[j] = u[N - 1 - j]
    state[H_COUNT] = count
    state[H_RESETS] = resets
    state[H_CPROJ] = cproj
    state[H_TRSCALE] = trscale
    state[H_SKIPPED] = skipped
    state[H_NV] = nv
    state[H_XI] = xi


@njit(cache=True)
def rels_run(state, u, y, err, xi_out, hist, hist_every):
    """Run the estimator over whole records (batch RELS or RML).

    Parameters
    ----------
    state : float64 buffer, updated in place
    u, y : float64 (N,), scaled, finite
    err : float64 (N,) out, a-priori prediction errors e(k)
    xi_out : float64 (N,) out, a-posteriori residuals ξ̂(k) of eq (19)
    hist : float64 (N // hist_every, n) out, θ̂ every ``hist_every`` samples
        (row r holds θ̂ after sample (r+1)·hist_every − 1); shape (0, n) for none
    hist_every : int ≥ 1
    """
    n = int(state[H_NA]) + int(state[H_NB]) + 1 + int(state[H_NC])
    if _is_rml(state) or (n + 3) // 4 * 4 > SIMD_MAX:
        _step_batch(state, u, y, err, xi_out, hist, hist_every)
    else:
        _rels_batch(state, u, y, err, xi_out, hist, hist_every)


@njit(cache=True)
def rels_step(state, u, y):
    """Streaming entry point: one sample (scaled), returns the a-priori error.

    Returns NaN only if ``u`` or ``y`` is not finite, in which case the state is left
    untouched; the Python wrapper turns that into a DataError.
    """
    if not (np.isfinite(u) and np.isfinite(y)):
        return np.nan
    theta, P, psi, g, ul, cw = _views(state)
    return _step(state, theta, P, psi, g, ul, cw, _hf_view(state), u, y, _is_rml(state))
