"""AVX-width (4 × float64) kernels of the P update (22), written as numba intrinsics.

Why intrinsics: numba runs LLVM with the SLP vectoriser off and cannot tell LLVM that
P, g and the next g do not alias, so the plain-loop form of the fused pass (update
P(k), accumulate the next gain P(k)ψ̂(k+1) in the same pass) keeps the next gain in
memory and is bound by stores. Here the rows of P are processed as ``m/4`` vectors of
``<4 x double>`` and the next gain lives in ``m/4`` vector registers for the whole pass
(``m`` is the padded size, a multiple of 4, see :mod:`._kernels`). The code is generated
once per n = 1..SIMD_MAX (K = ⌈n/4⌉ vectors per row) and selected by a switch on n at
run time, so row counts and lane counts are constants.

Arithmetic, element by element, in this order (plain IEEE operations, no FMA, no
reassociation beyond what is listed; the tests hold the kernels to these exact bits,
and the numpy reference of the estimator does the same operations):

* w_j = g_j · √(inv_den · inv_lam), j < m  (inv_den = 1/(λ + ψ̂ᵀPψ̂), inv_lam = 1/λ)
* P_ij ← P_ij · inv_lam − w_i · w_j, rows i < n, all m columns (``downdate``; with
  inv_lam = 1 the product P_ij · 1 is P_ij, so at λ = 1 it is ``downdate_gain``'s
  update bit for bit). w_i w_j = w_j w_i exactly, so the updated P is exactly
  symmetric. This is (P − g gᵀ·inv_den)·inv_lam, eq (22), with one multiply per
  entry fewer than forming (g_i g_j)·inv_den.
* g_j ← g_j + P_ij · r_i, i = 0..n−1 in order, from 0, over the updated P
  (``downdate_gain``) or over P as it is (``gain``, ``gain_sums``). (A fused
  multiply-add here was measured slower: its longer latency lengthens the add chain
  through the rows.)
* sums over the new g (``gain_sums``, ``downdate_gain``): the K = m/4 vectors
  r_c ⊙ θ_c (for ŷ = rᵀθ) and r_c ⊙ g_c (for s = rᵀg) are added pairwise, level by
  level ((v0 + v1), (v2 + v3), …; an odd last vector moves up unchanged), and the
  four lanes of the result as (l0 + l1) + (l2 + l3) — a short tree instead of one
  serial chain of n adds, which sat on the critical path of every sample;
  max(0, max_j |g_j|) over whole vectors
* tr P and min_i P_ii after an update (``downdate``, ``downdate_gain``): the n
  diagonal entries in the same pairwise tree (adjacent pairs, odd last entry moves
  up), the minimum as ``a if a < b else b`` (a NaN on the diagonal makes tr P NaN,
  and the guard resets P whatever the minimum says)

The padding (rows and entries ≥ n) is zero; the vector sums add its zero products.

On CPUs without AVX, LLVM splits each ``<4 x double>`` operation into SSE2 halves: the
same operations on the same elements, so the same results. The plain loops that
:mod:`._kernels` runs beyond SIMD_MAX do the same updates with serial sums. numba's
on-disk cache is keyed on the source file of the jitted function: after editing this
module, clear the ``__pycache__`` entries of ``_kernels.py`` (or touch it) so that its
kernels recompile.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

__all__: list[str] = []  # private: used by _kernels

#: largest number of 4-wide vectors per row handled here (m ≤ 4 · KMAX); larger
#: problems take the plain loops in _kernels
KMAX = 8
SIMD_MAX = 4 * KMAX

_F64 = ir.DoubleType()
_I64 = ir.IntType(64)
_I32 = ir.IntType(32)
_V4 = ir.VectorType(_F64, 4)
_ZERO_V4 = ir.Constant(_V4, [0.0, 0.0, 0.0, 0.0])
_SPLAT0 = ir.Constant(ir.VectorType(_I32, 4), [0, 0, 0, 0])


def _splat(builder, x):
    v = builder.insert_element(ir.Constant(_V4, ir.Undefined), x, ir.Constant(_I32, 0))
    return builder.shuffle_vector(v, ir.Constant(_V4, ir.Undefined), _SPLAT0)


def _vec_ptr(builder, base, index):
    return builder.bitcast(builder.gep(base, [index]), _V4.as_pointer())


def _i64(k):
    return ir.Constant(_I64, k)


def _llvm_intrinsic(module, name, fnty):
    """Declaration of the LLVM intrinsic ``name`` in ``module`` (once)."""
    try:
        return module.get_global(name)
    except KeyError:
        return ir.Function(module, fnty, name=name)


def _mul_add(builder, a, b, c):
    """c + a·b: a multiply, then an add (two roundings)."""
    return builder.fadd(c, builder.fmul(a, b))


def _tree(values, op):
    """Pairwise reduction, level by level: (v0 ∘ v1), (v2 ∘ v3), …; an odd last value
    moves up unchanged."""
    while len(values) > 1:
        values = [op(values[i], values[i + 1]) if i + 1 < len(values) else values[i]
                  for i in range(0, len(values), 2)]
    return values[0]


#: what a row pass does (``_pass_function``'s ``mode``) and how many values it hands
#: back through ``out``: DOWNDATE (tr P, min P_ii); DOWNDATE_GAIN_SUMS (ŷ, s, max|g|,
#: tr P, min P_ii); GAIN none; GAIN_SUMS (ŷ, s, max|g|)
DOWNDATE, DOWNDATE_GAIN_SUMS, GAIN, GAIN_SUMS = 0, 1, 2, 3
_N_OUT = {DOWNDATE: 2, DOWNDATE_GAIN_SUMS: 5, GAIN: 0, GAIN_SUMS: 3}
# The pass functions are linkonce_odr symbols shared by every kernel that calls them,
# so their names carry a digest of this file: a process that loads kernels compiled
# from two versions of it (a stale numba cache, an experiment) cannot link one
# version's calls to the other's code.
_TAG = hashlib.sha1(Path(__file__).read_bytes()).hexdigest()[:12]
_PASS_NAMES = {DOWNDATE: f"ehss_simd_downdate_{_TAG}",
               DOWNDATE_GAIN_SUMS: f"ehss_simd_downdate_gain_sums_{_TAG}",
               GAIN: f"ehss_simd_gain_{_TAG}",
               GAIN_SUMS: f"ehss_simd_gain_sums_{_TAG}"}
#: (P data, m, g data, r data, n, inv_den, inv_lam, θ data, out data); unused arguments
#: are passed anyway (the g pointer stands in for unused arrays)
_PASS_TYPE = ir.FunctionType(ir.VoidType(), [_F64.as_pointer(), _I64, _F64.as_pointer(),
                                             _F64.as_pointer(), _I64, _F64, _F64,
                                             _F64.as_pointer(), _F64.as_pointer()])


def _pass_function(module, mode):
    """The pass as an out-of-line LLVM function of ``module`` (defined once per module).

    Out of line on purpose: numba brackets the arrays an inlined helper receives with
    reference-count increments and decrements, and its pruning pass removes such a pair
    only when nothing between them branches. A single call keeps the pair in one basic
    block (pruned); the pass's own switch and loops inline would leave two atomic
    operations per array and call in the per-sample loop.
    """
    name = _PASS_NAMES[mode]
    try:
        return module.get_global(name)
    except KeyError:
        pass
    fn = ir.Function(module, _PASS_TYPE, name=name)
    fn.linkage = "linkonce_odr"
    fn.attributes.add("noinline")
    fn.attributes.add("nounwind")
    fn.attributes.add("optsize")  # no unrolling: two rows at once spilled g and acc
    P_data, m, g_data, r_data, nrow, inv_den, inv_lam, theta_data, out_data = fn.args
    builder = ir.IRBuilder(fn.append_basic_block("entry"))
    update = mode in (DOWNDATE, DOWNDATE_GAIN_SUMS)  # P is written
    accumulate = mode != DOWNDATE  # a new g = P r is summed
    sums = mode in (DOWNDATE_GAIN_SUMS, GAIN_SUMS)
    if update and accumulate:
        for arg in (P_data, g_data, r_data):
            arg.add_attribute("noalias")  # distinct buffers (the callers' contract)
    if update:
        sqrt = _llvm_intrinsic(module, "llvm.sqrt.f64", ir.FunctionType(_F64, [_F64]))
        scale = inv_den if mode == DOWNDATE_GAIN_SUMS else builder.fmul(inv_den, inv_lam)
        root = builder.call(sqrt, [scale])  # w = g √(inv_den · inv_lam)

    done = fn.append_basic_block("pass.done")
    other = fn.append_basic_block("pass.unsupported")
    # one case per n: the row count and the lanes summed are constants (m = 4K, K = ⌈n/4⌉)
    switch = builder.switch(nrow, other)
    for n in range(1, SIMD_MAX + 1):
        k = (n + 3) // 4
        entry = fn.append_basic_block(f"pass.n{n}")
        switch.add_case(_i64(n), entry)
        builder.position_at_end(entry)
        if update:
            root_v = _splat(builder, root)
            # w as vectors, formed once: g is not written until the pass is over
            w_v = [builder.fmul(builder.load(_vec_ptr(builder, g_data, _i64(4 * c)), align=8),
                                root_v) for c in range(k)]
        if mode == DOWNDATE:
            lam_v = _splat(builder, inv_lam)
        head = fn.append_basic_block(f"pass.n{n}.head")
        body = fn.append_basic_block(f"pass.n{n}.body")
        tail = fn.append_basic_block(f"pass.n{n}.tail")
        builder.branch(head)

        builder.position_at_end(head)
        i = builder.phi(_I64)
        acc = [builder.phi(_V4) for _ in range(k)] if accumulate else []
        i.add_incoming(_i64(0), entry)
        for a in acc:
            a.add_incoming(_ZERO_V4, entry)
        builder.cbranch(builder.icmp_signed("<", i, _i64(n)), body, tail)

        builder.position_at_end(body)
        row = builder.mul(i, m)
        if update:
            # w_i, the same product as lane i of w_v
            wi_v = _splat(builder, builder.fmul(builder.load(builder.gep(g_data, [i])), root))
        if accumulate:
            ri_v = _splat(builder, builder.load(builder.gep(r_data, [i])))
        acc_next = []
        for c in range(k):
            ptr = _vec_ptr(builder, P_data, builder.add(row, _i64(4 * c)))
            v = builder.load(ptr, align=8)
            if update:
                if mode == DOWNDATE:
                    v = builder.fmul(v, lam_v)
                v = builder.fsub(v, builder.fmul(wi_v, w_v[c]))
                builder.store(v, ptr, align=8)
            if accumulate:
                acc_next.append(_mul_add(builder, v, ri_v, acc[c]))
        latch = builder.block
        i.add_incoming(builder.add(i, _i64(1)), latch)
        for a, a_next in zip(acc, acc_next, strict=True):
            a.add_incoming(a_next, latch)
        builder.branch(head)

        builder.position_at_end(tail)
        for c, a in enumerate(acc):
            builder.store(a, _vec_ptr(builder, g_data, _i64(4 * c)), align=8)
        slot = 0
        if sums:
            _emit_sums(builder, acc, r_data, theta_data, out_data)
            slot = 3
        if update:
            _emit_trace_min(builder, n, m, P_data, out_data, slot)
        builder.branch(done)

    # n > SIMD_MAX: the callers never get here (they check SIMD_MAX first)
    builder.position_at_end(other)
    builder.branch(done)
    builder.position_at_end(done)
    builder.ret_void()
    return fn


def _lanes_sum(builder, v):
    """(l0 + l1) + (l2 + l3) of a <4 x double>."""
    lane = [builder.extract_element(v, ir.Constant(_I32, j)) for j in range(4)]
    return builder.fadd(builder.fadd(lane[0], lane[1]), builder.fadd(lane[2], lane[3]))


def _emit_sums(builder, acc, r_data, theta_data, out_data):
    """out[0:3] = (rᵀθ, rᵀg, max(0, max_j |g_j|)): the product vectors summed in the
    pairwise tree, then their lanes (see the module notes).

    The lanes beyond n hold exact zeros of r, θ and g, which change no sum and no
    maximum; ``maxnum`` ignores NaN, as the scalar ``if |g_j| > gmax`` does.
    """
    fabs = _llvm_intrinsic(builder.module, "llvm.fabs.v4f64", ir.FunctionType(_V4, [_V4]))
    maxnum = _llvm_intrinsic(builder.module, "llvm.maxnum.v4f64",
                             ir.FunctionType(_V4, [_V4, _V4]))
    gmax_v = _ZERO_V4
    py, ps = [], []
    for c, a in enumerate(acc):
        r_v = builder.load(_vec_ptr(builder, r_data, _i64(4 * c)), align=8)
        t_v = builder.load(_vec_ptr(builder, theta_data, _i64(4 * c)), align=8)
        py.append(builder.fmul(r_v, t_v))
        ps.append(builder.fmul(r_v, a))
        gmax_v = builder.call(maxnum, [gmax_v, builder.call(fabs, [a])])
    yhat = _lanes_sum(builder, _tree(py, builder.fadd))
    s = _lanes_sum(builder, _tree(ps, builder.fadd))
    lanes = [builder.extract_element(gmax_v, ir.Constant(_I32, lane)) for lane in range(4)]
    maxnum_s = _llvm_intrinsic(builder.module, "llvm.maxnum.f64",
                               ir.FunctionType(_F64, [_F64, _F64]))
    gmax = builder.call(maxnum_s, [builder.call(maxnum_s, lanes[:2]),
                                   builder.call(maxnum_s, lanes[2:])])
    for k, value in enumerate((yhat, s, gmax)):
        builder.store(value, builder.gep(out_data, [_i64(k)]))


def _emit_trace_min(builder, n, m, P_data, out_data, slot):
    """out[slot], out[slot + 1] = (tr P, min_i P_ii) of the updated P, i < n, each in
    the pairwise tree; the diagonal is read back after the pass."""
    step = builder.add(m, _i64(1))
    diag = [builder.load(builder.gep(P_data, [builder.mul(step, _i64(i))]))
            for i in range(n)]
    tr = _tree(diag, builder.fadd)
    dmin = _tree(diag, lambda a, b: builder.select(builder.fcmp_ordered("<", a, b), a, b))
    builder.store(tr, builder.gep(out_data, [_i64(slot)]))
    builder.store(dmin, builder.gep(out_data, [_i64(slot + 1)]))


def _emit_call(context, builder, sig, args, mode):
    """Lower one intrinsic call: extract the data pointers, call the pass function and
    hand its results back as a tuple (through a stack buffer of the caller).

    Argument orders: DOWNDATE (P, g, n, inv_den, inv_lam); GAIN (P, g, r, n);
    GAIN_SUMS (P, g, r, n, theta); DOWNDATE_GAIN_SUMS (P, g, r, n, inv_den, theta).
    """
    def data(k):
        return context.make_array(sig.args[k])(context, builder, value=args[k]).data

    def real(k):
        return context.cast(builder, args[k], sig.args[k], types.float64)

    P = context.make_array(sig.args[0])(context, builder, value=args[0])
    g_data = data(1)
    zero = ir.Constant(_F64, 0.0)
    one = ir.Constant(_F64, 1.0)
    theta_data = g_data
    if mode == DOWNDATE:
        n_arg, r_data, inv_den, inv_lam = 2, g_data, real(3), real(4)
    else:
        n_arg, r_data, inv_lam = 3, data(2), one
        inv_den = real(4) if mode == DOWNDATE_GAIN_SUMS else zero
        if mode == GAIN_SUMS:
            theta_data = data(4)
        elif mode == DOWNDATE_GAIN_SUMS:
            theta_data = data(5)
    count = _N_OUT[mode]
    out = cgutils.alloca_once(builder, ir.ArrayType(_F64, max(count, 1)))
    out_data = builder.bitcast(out, _F64.as_pointer())
    nrow = context.cast(builder, args[n_arg], sig.args[n_arg], types.intp)
    m = builder.extract_value(P.shape, 1)
    fn = _pass_function(builder.module, mode)
    builder.call(fn, [P.data, m, g_data, r_data, nrow, inv_den, inv_lam, theta_data,
                      out_data])
    if count == 0:
        return context.get_dummy_value()
    values = [builder.load(builder.gep(out_data, [_i64(k)])) for k in range(count)]
    return context.make_tuple(builder, sig.return_type, values)


@intrinsic
def downdate_gain(typingctx, P, g, r, n, inv_den, theta):
    """In place: P ← P − w wᵀ (rows < n, w = g √inv_den), then g ← P r.

    Returns (ŷ, s, max|g_j|, tr P, min P_ii): rᵀθ and rᵀg for the new g, and the
    trace and smallest diagonal entry of the updated P (see the module notes for the
    order of every sum). ``P`` (m, m) C-contiguous with m a multiple of 4 and
    n ≤ SIMD_MAX; ``g``, ``r`` and ``theta`` length m, zero beyond n; distinct buffers.
    """
    sig = types.UniTuple(types.float64, 5)(P, g, r, n, inv_den, theta)

    def codegen(context, builder, sig, args):
        return _emit_call(context, builder, sig, args, DOWNDATE_GAIN_SUMS)

    return sig, codegen


@intrinsic
def downdate(typingctx, P, g, n, inv_den, inv_lam):
    """In place: P ← P·inv_lam − w wᵀ (rows < n, w = g √(inv_den·inv_lam)), eq (22).

    Returns (tr P, min P_ii) of the updated P. ``P`` (m, m) C-contiguous with m a
    multiple of 4 and m ≤ SIMD_MAX; ``g`` length m.
    """
    sig = types.UniTuple(types.float64, 2)(P, g, n, inv_den, inv_lam)

    def codegen(context, builder, sig, args):
        return _emit_call(context, builder, sig, args, DOWNDATE)

    return sig, codegen


@intrinsic
def gain(typingctx, P, g, r, n):
    """g ← P r for symmetric P: g_j = Σ_i P_ij r_i, i = 0..n−1 in order (row axpys).

    ``P`` (m, m) C-contiguous with m a multiple of 4 and m ≤ SIMD_MAX; ``g`` and ``r``
    length m (``r`` zero beyond n, not aliasing ``g``).
    """
    sig = types.void(P, g, r, n)

    def codegen(context, builder, sig, args):
        return _emit_call(context, builder, sig, args, GAIN)

    return sig, codegen


@intrinsic
def gain_sums(typingctx, P, g, r, n, theta):
    """``gain``, then returns (rᵀθ, rᵀg, max(0, max_j |g_j|)).

    With r = ψ̂(k) and θ = θ̂(k−1) these are ŷ (eq 20), ψ̂ᵀPψ̂ (eq 21) and the size of
    the gain for the overflow check, summed in the pairwise tree of the module notes.
    ``theta`` length m, zero beyond n; all distinct buffers.
    """
    sig = types.UniTuple(types.float64, 3)(P, g, r, n, theta)

    def codegen(context, builder, sig, args):
        return _emit_call(context, builder, sig, args, GAIN_SUMS)

    return sig, codegen
