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
reassociation, so the results are bit for bit those of the obvious loops, and of the
numpy reference in the tests):

* P_ij ← P_ij − (g_i · g_j) · inv_den               (rows i < n, all m columns;
  ``downdate_gain``; inv_den = 1/(λ + ψ̂ᵀPψ̂))
* P_ij ← (P_ij − (g_i · g_j) · inv_den) · inv_lam   (``downdate``)
* g_j ← Σ_i P_ij r_i, i = 0..n−1 left to right, starting from 0.0, over the updated P
  (``downdate_gain``) or over P as it is (``gain``, ``gain_sums``)
* with the new g, from its registers (``gain_sums``, ``downdate_gain``):
  rᵀθ and rᵀg summed j = 0..n−1 left to right, max(0, max_j |g_j|); and after the
  update (``downdate_gain``) tr P and min_i P_ii, read back and summed i = 0..n−1

g_i g_j = g_j g_i exactly, so the updated P is exactly symmetric. Rows i ≥ n are the
zero padding and are not touched. (Measured and not kept, see BENCHMARKS.md:
w = g·√inv_den with P − w wᵀ, one multiply less per entry, no faster; the trace and
smallest diagonal entry summed inside the row loop, slower.)

On CPUs without AVX, LLVM splits each ``<4 x double>`` operation into SSE2 halves: the
same operations on the same elements, so the same results. numba's on-disk cache is
keyed on the source file of the jitted function: after editing this module, clear the
``__pycache__`` entries of ``_kernels.py`` (or touch it) so that its kernels recompile.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

from llvmlite import ir
from numba import types
from numba.extending import intrinsic

__all__: list[str] = []  # private: used by _kernels

#: largest number of 4-wide vectors per row handled here (m ≤ 4 · KMAX); larger
#: problems take the plain loops in _kernels (same arithmetic, same bits)
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


#: what a row pass does (``_pass_function``'s ``mode``); the *_SUMS modes also write
#: (ψ̂ᵀθ̂, ψ̂ᵀg, max|g_j|) for the new g and r = ψ̂ (see ``gain_sums``)
DOWNDATE, DOWNDATE_GAIN_SUMS, GAIN, GAIN_SUMS = 0, 1, 2, 3
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
            den_v = _splat(builder, inv_den)
            # g as vectors, loaded once: g is not written until the pass is over
            g_v = [builder.load(_vec_ptr(builder, g_data, _i64(4 * c)), align=8)
                   for c in range(k)]
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
            gi_v = _splat(builder, builder.load(builder.gep(g_data, [i])))
        if accumulate:
            ri_v = _splat(builder, builder.load(builder.gep(r_data, [i])))
        acc_next = []
        for c in range(k):
            ptr = _vec_ptr(builder, P_data, builder.add(row, _i64(4 * c)))
            v = builder.load(ptr, align=8)
            if update:
                t = builder.fmul(builder.fmul(gi_v, g_v[c]), den_v)
                v = builder.fsub(v, t)
                if mode == DOWNDATE:
                    v = builder.fmul(v, lam_v)
                builder.store(v, ptr, align=8)
            if accumulate:
                acc_next.append(builder.fadd(acc[c], builder.fmul(v, ri_v)))
        latch = builder.block
        i.add_incoming(builder.add(i, _i64(1)), latch)
        for a, a_next in zip(acc, acc_next, strict=True):
            a.add_incoming(a_next, latch)
        builder.branch(head)

        builder.position_at_end(tail)
        for c, a in enumerate(acc):
            builder.store(a, _vec_ptr(builder, g_data, _i64(4 * c)), align=8)
        if sums:
            _emit_sums(builder, acc, n, r_data, theta_data, out_data)
        if update and sums:
            _emit_trace_min(builder, n, m, P_data, out_data)
        builder.branch(done)

    # n > SIMD_MAX: the callers never get here (they check SIMD_MAX first)
    builder.position_at_end(other)
    builder.branch(done)
    builder.position_at_end(done)
    builder.ret_void()
    return fn


def _llvm_intrinsic(module, name, fnty):
    """Declaration of the LLVM intrinsic ``name`` in ``module`` (once)."""
    try:
        return module.get_global(name)
    except KeyError:
        return ir.Function(module, fnty, name=name)


def _emit_sums(builder, acc, n, r_data, theta_data, out_data):
    """out = (rᵀθ, rᵀg, max(0, max_j |g_j|)) over j < n, the sums left to right.

    The same operations as the scalar loops. The max runs over whole vectors: the lanes
    beyond n hold exact zeros of g, which change no maximum; ``maxnum`` ignores NaN, as
    the scalar ``if |g_j| > gmax`` does.
    """
    yhat = ir.Constant(_F64, 0.0)
    s = ir.Constant(_F64, 0.0)
    fabs = _llvm_intrinsic(builder.module, "llvm.fabs.v4f64", ir.FunctionType(_V4, [_V4]))
    maxnum = _llvm_intrinsic(builder.module, "llvm.maxnum.v4f64",
                             ir.FunctionType(_V4, [_V4, _V4]))
    gmax_v = _ZERO_V4
    for c, a in enumerate(acc):
        r_v = builder.load(_vec_ptr(builder, r_data, _i64(4 * c)), align=8)
        t_v = builder.load(_vec_ptr(builder, theta_data, _i64(4 * c)), align=8)
        py = builder.fmul(r_v, t_v)
        ps = builder.fmul(r_v, a)
        for lane in range(min(4, n - 4 * c)):
            yhat = builder.fadd(yhat, builder.extract_element(py, ir.Constant(_I32, lane)))
            s = builder.fadd(s, builder.extract_element(ps, ir.Constant(_I32, lane)))
        gmax_v = builder.call(maxnum, [gmax_v, builder.call(fabs, [a])])
    lanes = [builder.extract_element(gmax_v, ir.Constant(_I32, lane)) for lane in range(4)]
    maxnum_s = _llvm_intrinsic(builder.module, "llvm.maxnum.f64",
                               ir.FunctionType(_F64, [_F64, _F64]))
    gmax = builder.call(maxnum_s, [builder.call(maxnum_s, lanes[:2]),
                                   builder.call(maxnum_s, lanes[2:])])
    for k, value in enumerate((yhat, s, gmax)):
        builder.store(value, builder.gep(out_data, [_i64(k)]))


def _emit_trace_min(builder, n, m, P_data, out_data):
    """out[3:5] = (tr P, min_i P_ii) of the updated P, as ``_trace_min`` (i < n in order).

    The diagonal is read back after the pass; ``fcmp olt`` + select is the scalar
    ``if P_ii < dmin: dmin = P_ii`` (NaN never wins).
    """
    tr = ir.Constant(_F64, 0.0)
    dmin = ir.Constant(_F64, float("inf"))
    step = builder.add(m, _i64(1))
    for i in range(n):
        d = builder.load(builder.gep(P_data, [builder.mul(step, _i64(i))]))
        tr = builder.fadd(tr, d)
        dmin = builder.select(builder.fcmp_ordered("<", d, dmin), d, dmin)
    builder.store(tr, builder.gep(out_data, [_i64(3)]))
    builder.store(dmin, builder.gep(out_data, [_i64(4)]))


def _emit_call(context, builder, sig, args, mode):
    """Lower one intrinsic call: extract the data pointers and call the pass function.

    Argument orders: DOWNDATE (P, g, n, inv_den, inv_lam); GAIN (P, g, r, n);
    GAIN_SUMS (P, g, r, n, theta, out); DOWNDATE_GAIN_SUMS (P, g, r, n, inv_den,
    theta, out).
    """
    def data(k):
        return context.make_array(sig.args[k])(context, builder, value=args[k]).data

    def real(k):
        return context.cast(builder, args[k], sig.args[k], types.float64)

    P = context.make_array(sig.args[0])(context, builder, value=args[0])
    g_data = data(1)
    zero = ir.Constant(_F64, 0.0)
    one = ir.Constant(_F64, 1.0)
    if mode == DOWNDATE:
        n_arg, r_data, inv_den, inv_lam = 2, g_data, real(3), real(4)
        theta_data = out_data = g_data
    else:
        n_arg, r_data, inv_lam = 3, data(2), one
        inv_den = real(4) if mode == DOWNDATE_GAIN_SUMS else zero
        if mode == GAIN:
            theta_data = out_data = g_data
        else:
            first = 5 if mode == DOWNDATE_GAIN_SUMS else 4
            theta_data, out_data = data(first), data(first + 1)
    nrow = context.cast(builder, args[n_arg], sig.args[n_arg], types.intp)
    m = builder.extract_value(P.shape, 1)
    fn = _pass_function(builder.module, mode)
    builder.call(fn, [P.data, m, g_data, r_data, nrow, inv_den, inv_lam, theta_data,
                      out_data])
    return context.get_dummy_value()


@intrinsic
def downdate_gain(typingctx, P, g, r, n, inv_den, theta, out):
    """In place: P ← P − g gᵀ·inv_den (rows < n), then g ← P r.

    out[0:3] as ``gain_sums`` (for the new g), out[3:5] = (tr P, min_i P_ii) of the
    updated P, summed as ``_kernels._trace_min``. ``P`` (m, m) C-contiguous with m a
    multiple of 4 and n ≤ SIMD_MAX; ``g``, ``r`` and ``theta`` length m, zero beyond n;
    ``out`` length ≥ 5; all distinct buffers.
    """
    sig = types.void(P, g, r, n, inv_den, theta, out)

    def codegen(context, builder, sig, args):
        return _emit_call(context, builder, sig, args, DOWNDATE_GAIN_SUMS)

    return sig, codegen


@intrinsic
def downdate(typingctx, P, g, n, inv_den, inv_lam):
    """In place: P ← (P − g gᵀ·inv_den)·inv_lam (rows < n).

    ``P`` (m, m) C-contiguous with m a multiple of 4 and m ≤ SIMD_MAX; ``g`` length m.
    """
    sig = types.void(P, g, n, inv_den, inv_lam)

    def codegen(context, builder, sig, args):
        return _emit_call(context, builder, sig, args, DOWNDATE)

    return sig, codegen


@intrinsic
def gain(typingctx, P, g, r, n):
    """g ← P r for symmetric P: g_j = Σ_i P_ij r_i, i = 0..n−1 left to right (row axpys).

    ``P`` (m, m) C-contiguous with m a multiple of 4 and m ≤ SIMD_MAX; ``g`` and ``r``
    length m (``r`` zero beyond n, not aliasing ``g``).
    """
    sig = types.void(P, g, r, n)

    def codegen(context, builder, sig, args):
        return _emit_call(context, builder, sig, args, GAIN)

    return sig, codegen


@intrinsic
def gain_sums(typingctx, P, g, r, n, theta, out):
    """``gain``, then out[0] = rᵀθ, out[1] = rᵀg, out[2] = max(0, max_j |g_j|).

    With r = ψ̂(k) and θ = θ̂(k−1) these are ŷ (eq 20), ψ̂ᵀPψ̂ (eq 21) and the size of
    the gain for the overflow check, summed left to right as the scalar loops do.
    ``theta`` length m, zero beyond n; ``out`` length ≥ 3; all distinct buffers.
    """
    sig = types.void(P, g, r, n, theta, out)

    def codegen(context, builder, sig, args):
        return _emit_call(context, builder, sig, args, GAIN_SUMS)

    return sig, codegen
