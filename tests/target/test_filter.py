"""The target filter against scipy, and its swaps against their definition."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from ehss.errors import DataError, ParameterError
from ehss.target import MAX_PREVIEW, MAX_SECTIONS, MAX_TAPS, Compensator, CompensatorFilter
from ehss.target import filter as target_filter
from ehss.target._kernels import crossfade_block, filter_block

from .naive import random_compensator, reference_filter, reference_settle, reference_swaps

FS = 5000.0


def _atol(y: np.ndarray) -> float:
    # The filter and the references do the same products; np.convolve sums the taps in
    # another order, so results differ by rounding: at most about n_taps * eps * sum|h v|
    # (2048 * 1.1e-16 * |y| ~ 2.3e-13 |y| for these unit-gain compensators). 1e-12 of the
    # output's scale bounds that with room, and is far below any error of the arithmetic
    # itself (a wrong coefficient or sample shows at 1e-3 or more).
    return 1e-12 * max(1.0, float(np.max(np.abs(y))))


@pytest.mark.parametrize("n_sections, n_taps", [(0, 1), (1, 1), (3, 17), (MAX_SECTIONS,
                                                                          MAX_TAPS)])
def test_filter_equals_sosfilt_then_convolve(rng, n_sections, n_taps):
    c = random_compensator(rng, n_sections, n_taps, preview=4)
    x = rng.standard_normal(3000)
    y = CompensatorFilter(c).process(x)
    expected = reference_filter(c, x)
    assert_allclose(y, expected, rtol=0, atol=_atol(expected))


def test_blocks_of_any_size_and_single_steps_give_the_same_drive(rng):
    c = random_compensator(rng, 4, 40)
    new = random_compensator(rng, 2, 9)
    x = rng.standard_normal(2000)

    def run(cuts):
        f = CompensatorFilter(c)
        out = []
        for lo, hi in zip(cuts[:-1], cuts[1:], strict=True):
            if lo == 700:
                assert f.load(new, apply_index=900, crossfade=300)
            out.append(f.process(x[lo:hi]))
        return np.concatenate(out)

    whole = run([0, 700, 2000])
    pieces = run(sorted({0, 700, 2000, *rng.integers(1, 2000, 40).tolist()}))
    f = CompensatorFilter(c)
    steps = []
    for k in range(2000):
        if k == 700:
            f.load(new, apply_index=900, crossfade=300)
        steps.append(f.step(x[k]))
    # one arithmetic, sample by sample, whatever the blocks: exactly equal
    assert_array_equal(pieces, whole)
    assert_array_equal(np.array(steps), whole)


def test_pure_python_kernel_equals_the_compiled_one(rng):
    # the numba kernel and the same code run by the interpreter, at the largest sizes
    c = random_compensator(rng, MAX_SECTIONS, MAX_TAPS)
    state = {}
    for name, kernel in (("numba", filter_block), ("python", filter_block.py_func)):
        sos = np.zeros((MAX_SECTIONS, 6))
        sos[:] = c.sos
        z, hist, taps = np.zeros((MAX_SECTIONS, 2)), np.zeros(MAX_TAPS), c.taps.copy()
        x = np.random.default_rng(3).standard_normal(400)
        y = np.empty_like(x)
        pos = kernel(sos, MAX_SECTIONS, z, taps, MAX_TAPS, hist, 0, x, y)
        state[name] = (y, z, hist, pos)
    # the same operations in the same order on IEEE doubles (numba runs without
    # fastmath, so no fused multiply-add): equal to the last bit
    for a, b in zip(state["numba"], state["python"], strict=True):
        assert_array_equal(a, b)


def test_delay_runs_the_reference_unchanged():
    x = np.arange(1.0, 21.0)
    f = CompensatorFilter(Compensator.delay(3, fs_hz=FS))
    # the input is r[k + 3]: the drive is r[k], the input three samples late
    assert_array_equal(f.process(x), np.r_[0.0, 0.0, 0.0, x[:-3]])
    assert f.preview == 3


def test_a_swap_loaded_ahead_runs_in_shadow_then_cross_fades(rng):
    old = random_compensator(rng, 3, 12, preview=2)
    new = random_compensator(rng, 5, 30, preview=2)
    x = rng.standard_normal(6000)
    f = CompensatorFilter(old)
    y1 = f.process(x[:1000])
    assert f.load(new, apply_index=2500, crossfade=1200)
    y2 = f.process(x[1000:])
    expected = reference_swaps(x, old, [(1000, new, 2500, 1200)])
    assert_allclose(np.r_[y1, y2], expected, rtol=0, atol=_atol(expected))
    assert f.active is new and f.incoming is None
    assert f.counters == {"loads": 1, "swaps": 1, "refused_preview": 0,
                          "refused_sample_rate": 0, "busy": 0, "superseded": 0, "late": 0}


def test_the_weights_rise_linearly_from_one_filter_to_the_other():
    # two constant filters (gains 1 and 3) show the weights themselves
    one = Compensator(sos=[], taps=[1.0], preview=0, fs_hz=FS)
    three = Compensator(sos=[], taps=[3.0], preview=0, fs_hz=FS)
    f = CompensatorFilter(one)
    f.load(three, apply_index=5, crossfade=4)
    y = f.process(np.ones(12))
    # w = 1/4, 2/4, 3/4, 4/4 from sample 5: 1 + 2 w
    assert_array_equal(y, [1, 1, 1, 1, 1, 1.5, 2, 2.5, 3, 3, 3, 3])


@pytest.mark.parametrize("crossfade", [0, 1])
def test_no_cross_fade_switches_at_the_apply_index(crossfade):
    f = CompensatorFilter(Compensator(sos=[], taps=[1.0], preview=0, fs_hz=FS))
    f.load(Compensator(sos=[], taps=[2.0], preview=0, fs_hz=FS), apply_index=3,
           crossfade=crossfade)
    assert_array_equal(f.process(np.ones(6)), [1, 1, 1, 2, 2, 2])


def test_a_swap_loaded_after_its_apply_index_fades_in_once_settled(rng):
    old = random_compensator(rng, 2, 5)
    new = random_compensator(rng, 2, 5)
    x = rng.standard_normal(3000)
    f = CompensatorFilter(old)
    y1 = f.process(x[:1700])
    f.load(new, apply_index=1000, crossfade=500)
    y2 = f.process(x[1700:])
    settle = reference_settle(new)
    expected = reference_swaps(x, old, [(1700, new, 1700 + settle, 500)])
    assert_allclose(np.r_[y1, y2], expected, rtol=0, atol=_atol(expected))
    assert f.counters["late"] == 1


@pytest.mark.parametrize("late_by", [1, 40, 10_000])
def test_a_late_load_gives_the_drive_of_one_that_came_in_time(rng, late_by):
    # a datagram that comes after its apply index (a slow link, a busy host) must not
    # fade in a filter still starting up from rest: its start-up transient would be as
    # large as the reference. It runs its settling time in shadow first, so its drive
    # is the one a load that came just in time gives, sample for sample.
    old = random_compensator(rng, 3, 40)
    new = random_compensator(rng, 3, 40)
    x = rng.standard_normal(4000)
    settle = reference_settle(new)
    drives = []
    for apply_index in (1000 + settle, max(0, 1000 + settle - late_by)):
        f = CompensatorFilter(old)
        y = f.process(x[:1000])
        f.load(new, apply_index=apply_index, crossfade=200)
        drives.append(np.r_[y, f.process(x[1000:])])
    assert_array_equal(drives[1], drives[0])
    settled = reference_filter(new, x[1000:])
    assert_allclose(drives[0][1000 + settle + 200:], settled[settle + 200:], rtol=0,
                    atol=_atol(settled))


def test_the_settling_time_is_the_slowest_modes(rng):
    for n in (0, 1, 5, MAX_SECTIONS):
        c = random_compensator(rng, n, int(rng.integers(1, MAX_TAPS + 1)))
        assert c.settle_samples == reference_settle(c)
    near = Compensator(sos=[[1.0, 0, 0, 1.0, -2 * 0.9999, 0.9999**2]], taps=[1.0],
                       preview=0, fs_hz=FS)           # a double real pole at 0.9999
    assert near.settle_samples == 1 + math.ceil(7.0 / -math.log(0.9999))


def test_a_shadow_long_enough_makes_the_new_filter_start_settled(rng):
    # an FIR compensator loaded n_taps samples ahead has its whole memory filled when it
    # fades in: swapping to the same compensator changes nothing
    c = Compensator(sos=[], taps=rng.standard_normal(50), preview=0, fs_hz=FS)
    x = rng.standard_normal(1000)
    plain = CompensatorFilter(c).process(x)
    f = CompensatorFilter(c)
    a = f.process(x[:200])
    f.load(c, apply_index=250, crossfade=100)
    y = np.r_[a, f.process(x[200:])]
    # during the fade (1 - w) u + w u is u up to the rounding of 1 - w, two products and
    # a sum: a few units in the last place of |u| (eps = 2.2e-16)
    assert_allclose(y, plain, rtol=1e-15, atol=0)
    # before and after it, the drive is the one filter's, to the last bit
    assert_array_equal(y[:250], plain[:250])
    assert_array_equal(y[350:], plain[350:])


def test_a_load_during_a_cross_fade_waits_and_a_third_is_busy(rng):
    c0, c1, c2, c3 = (random_compensator(rng, 2, 4) for _ in range(4))
    x = rng.standard_normal(2000)
    f = CompensatorFilter(c0)
    y = [f.process(x[:100])]
    assert f.load(c1, apply_index=200, crossfade=400)        # fades 200..599
    y.append(f.process(x[100:300]))
    assert f.load(c2, apply_index=0, crossfade=100)          # waits until 600
    assert not f.load(c3, apply_index=0, crossfade=100)      # refused: busy
    assert f.waiting
    y.append(f.process(x[300:]))
    # c2 taken up at 600 runs its settling time in shadow before it fades in
    expected = reference_swaps(x, c0, [(100, c1, 200, 400),
                                       (600, c2, 600 + reference_settle(c2), 100)])
    assert_allclose(np.concatenate(y), expected, rtol=0, atol=_atol(expected))
    assert f.counters == {"loads": 2, "swaps": 2, "refused_preview": 0,
                          "refused_sample_rate": 0, "busy": 1, "superseded": 0, "late": 1}


def test_a_newer_load_replaces_a_filter_still_in_shadow(rng):
    c0, c1, c2 = (random_compensator(rng, 2, 4) for _ in range(3))
    x = rng.standard_normal(1500)
    f = CompensatorFilter(c0)
    y = [f.process(x[:100])]
    f.load(c1, apply_index=900, crossfade=100)
    y.append(f.process(x[100:400]))
    f.load(c2, apply_index=800, crossfade=200)
    y.append(f.process(x[400:]))
    expected = reference_swaps(x, c0, [(400, c2, 800, 200)])
    assert_allclose(np.concatenate(y), expected, rtol=0, atol=_atol(expected))
    assert f.counters["superseded"] == 1 and f.counters["swaps"] == 1


def test_a_compensator_with_another_preview_is_refused(rng):
    f = CompensatorFilter(Compensator.delay(2, fs_hz=FS))
    assert not f.load(random_compensator(rng, 1, 3, preview=3), 0, 10)
    assert f.counters["refused_preview"] == 1 and not f.waiting


def test_a_compensator_for_another_sample_rate_is_refused(rng):
    f = CompensatorFilter(Compensator.delay(0, fs_hz=FS))
    # 0.1 % is the tolerance: 5005.5 Hz (0.11 %) and 2500 Hz are refused
    assert not f.load(random_compensator(rng, 1, 3, fs_hz=FS * 1.0011), 0, 10)
    assert not f.load(random_compensator(rng, 1, 3, fs_hz=FS / 2), 0, 10)
    assert f.counters["refused_sample_rate"] == 2 and not f.waiting
    assert f.load(random_compensator(rng, 1, 3, fs_hz=FS * 0.9991), 0, 10)


def test_pure_python_path_equals_the_compiled_one_over_swaps(rng, monkeypatch):
    c = [random_compensator(rng, 3, 20) for _ in range(3)]
    x = rng.standard_normal(6000)

    def run():
        f = CompensatorFilter(c[0])
        y = [f.process(x[:500])]
        f.load(c[1], 1500, 1000)
        y.append(f.process(x[500:3000]))
        f.load(c[2], 2000, 700)    # late
        y.append(f.process(x[3000:]))
        return np.concatenate(y)

    compiled = run()
    monkeypatch.setattr(target_filter, "filter_block", filter_block.py_func)
    monkeypatch.setattr(target_filter, "crossfade_block", crossfade_block.py_func)
    # the same code, compiled without fastmath or interpreted: equal to the last bit
    assert_array_equal(run(), compiled)


@pytest.mark.parametrize("kwargs, match", [
    ({"sos": [[1, 0, 0, 1, 0, 1.0]]}, "unit circle"),           # poles on |z| = 1
    ({"sos": [[1, 0, 0, 1, -2.1, 1.1]]}, "unit circle"),        # a pole at 1.1
    ({"sos": [[1, 0, 0, 1, 1.0, 0.0]]}, "unit circle"),         # a pole at -1
    ({"sos": [[1, 0, 0, 2, 0, 0.0]]}, "a0 = 1"),
    ({"sos": [[np.nan, 0, 0, 1, 0, 0]]}, "finite"),
    ({"taps": [np.inf]}, "finite"),
    ({"sos": np.tile([1.0, 0, 0, 1, 0, 0], (MAX_SECTIONS + 1, 1))}, "n_sections <= 16"),
    ({"taps": np.ones(MAX_TAPS + 1)}, f"1 to {MAX_TAPS} taps"),
    ({"sos": [1.0, 0, 0, 1, 0, 0]}, "must be \\(n_sections, 6\\)"),
    ({"preview": MAX_PREVIEW + 1}, "preview"),
    ({"preview": -1}, "preview"),
    ({"fs_hz": 0.0}, "fs_hz"),
])
def test_compensators_that_cannot_run_are_refused(kwargs, match):
    args = {"sos": [[1.0, 0.5, 0, 1, -0.5, 0.25]], "taps": [1.0], "preview": 0,
            "fs_hz": FS} | kwargs
    with pytest.raises(ParameterError, match=match):
        Compensator(**args)


def test_a_section_just_inside_the_unit_circle_is_accepted():
    # poles at 0.999 e^{±j 0.3}
    r, th = 0.999, 0.3
    Compensator(sos=[[1, 0, 0, 1, -2 * r * np.cos(th), r * r]], taps=[], preview=0,
                fs_hz=FS)


def test_empty_taps_mean_no_fir_part():
    c = Compensator(sos=np.zeros((0, 6)), taps=[], preview=0, fs_hz=FS)
    assert c.taps.tolist() == [1.0] and c.n_sections == 0


def test_a_non_finite_input_is_refused_and_leaves_the_filter_as_it_was(rng):
    c = random_compensator(rng, 2, 5)
    x = rng.standard_normal(100)
    f = CompensatorFilter(c)
    f.process(x[:50])
    with pytest.raises(DataError, match="not finite"):
        f.process(np.r_[x[50:60], np.nan])
    assert f.index == 50
    assert_array_equal(np.r_[CompensatorFilter(c).process(x[:50]), f.process(x[50:])],
                       CompensatorFilter(c).process(x))
