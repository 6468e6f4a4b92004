"""Change figures against analytic answers; the sequential test's threshold, calibration
and alarm logic against Monte-Carlo run lengths and coverage; the baseline's prediction
errors against the noise that made the record."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.signal import lfilter

import ehss
from ehss.errors import ParameterError
from ehss.live.detect import (
    BaselineResidual,
    Calibration,
    DetectionSettings,
    Detector,
    block_statistic,
    calibrate,
    check_baseline,
    cusum_threshold,
    dominant_pole,
    figures,
    output_error_predictor,
    whitening_filter,
)


def test_dominant_pole_of_a_damped_pair():
    # z = r e^{±jθ} with r = e^{-σ dt}, θ = ω dt  →  s = −σ + jω exactly
    dt, sigma, omega = 1e-3, 30.0, 2 * np.pi * 25.0
    r, th = math.exp(-sigma * dt), omega * dt
    a = np.poly([r * np.exp(1j * th), r * np.exp(-1j * th), 0.3])
    s = dominant_pole(a.real, dt)
    assert s.real == pytest.approx(-sigma, rel=1e-9)   # roots of a cubic: ~1e-13
    assert s.imag == pytest.approx(omega, rel=1e-9)


def test_figures_of_a_pure_gain_change():
    # H = 2 H_ref: every point 6.0206 dB apart, same poles
    h_ref = np.exp(1j * np.linspace(0, 3, 20)) / np.linspace(1, 4, 20)
    f = figures(2 * h_ref, h_ref, -5 + 3j, -5 + 3j)
    np.testing.assert_allclose(f, [20 * math.log10(2), 20 * math.log10(2), 0.0], atol=1e-12)


def test_model_response_matches_armax_model():
    # the channel's cheap response from θ̂ equals ArmaxModel.frequency_response
    from ehss.live.channel import ChannelProcessor, EstimatorSettings

    est = EstimatorSettings(na=2, nb=1, nc=0, delay=1, u_scale=1.0, y_scale=1.0)
    proc = ChannelProcessor("1", 100.0, est, DetectionSettings(learn_s=1.0, band_hz=(1, 20)))
    rng = np.random.default_rng(3)
    u = rng.standard_normal(300)
    y = lfilter([0, 0.5, 0.2], [1, -1.2, 0.5], u)
    proc.feed(u, y)
    proc.evaluate(3.0, proc.capture())
    grid, h, _ = proc.model_response()
    np.testing.assert_allclose(h, proc.estimator.model.frequency_response(grid), rtol=1e-12)


def test_dominant_pole_in_band_only():
    # a slow real pole at 0.2 Hz (closest to the circle) and a pair at 25 Hz
    dt = 1e-3
    zs = [np.exp(-2 * np.pi * 0.2 * dt),
          np.exp((-30 + 2j * np.pi * 25) * dt), np.exp((-30 - 2j * np.pi * 25) * dt)]
    a = np.poly(zs).real
    assert abs(dominant_pole(a, dt)) == pytest.approx(2 * np.pi * 0.2, rel=1e-6)
    s = dominant_pole(a, dt, (1.0, 50.0))
    assert s.imag == pytest.approx(2 * np.pi * 25, rel=1e-9)
    assert math.isnan(dominant_pole(a, dt, (60.0, 100.0)).real)


@pytest.mark.parametrize("kw", [{"compare": "x"}, {"frf_db": 0}, {"clear_s": -1},
                                {"band_hz": (5, 1)}, {"false_alarm_hours": 0},
                                {"false_alarm_hours": math.inf}])
def test_bad_settings(kw):
    with pytest.raises(ParameterError):
        DetectionSettings(**kw)


# ---------------------------------------------------------------- the sequential test
def _run_lengths(threshold: float, n_runs: int, max_len: int, rng) -> np.ndarray:
    """Run lengths to a crossing of S_k = max(0, S_{k−1} + z_k − 1/2) ≥ h, z ~ N(0, 1):
    all runs at once, written from Page's recursion (independent of :class:`Detector`)."""
    s = np.zeros(n_runs)
    length = np.full(n_runs, max_len)
    alive = np.ones(n_runs, dtype=bool)
    for k in range(1, max_len + 1):
        s = np.maximum(0.0, s + rng.standard_normal(n_runs) - 0.5)
        hit = alive & (s >= threshold)
        length[hit] = k
        alive &= ~hit
        if not alive.any():
            break
    return length


@pytest.mark.parametrize("arl", [100.0, 1000.0])
def test_cusum_threshold_gives_the_run_length_asked_for(arl):
    rng = np.random.default_rng(7)
    h = cusum_threshold(arl)
    lengths = _run_lengths(h, 1500, int(30 * arl), rng)
    # run lengths are near-exponential: the mean of 1500 has a standard error of
    # ≈ arl/√1500 = 2.6 %; Siegmund's approximation, exact in the limit of small
    # increments, is off by a few % for unit Gaussian steps: 12 % is 4.5 standard
    # errors, and a threshold set without the overshoot correction (b = h) would run
    # 3.2–3.4 times longer than asked for
    assert lengths.mean() == pytest.approx(arl, rel=0.12)


def test_cusum_threshold_grows_with_the_log_of_the_run_length():
    # ARL ≈ e^{2κb}/(2κ²) for large b: h(ARL·e) − h(ARL) → 1/(2κ) = 1 σ
    assert cusum_threshold(1e8 * math.e) - cusum_threshold(1e8) == pytest.approx(1.0,
                                                                                 abs=1e-6)


def test_detector_runs_as_long_as_its_rate_between_false_alarms():
    # the detector's own statistic and step on N(0, 1) blocks with a known calibration:
    # the mean time to its first alarm is the run length it is set for
    rng = np.random.default_rng(11)
    arl = 200.0
    cal = Calibration(mean=0.0, sd=1.0, mean_hat=0.0, sd_hat=1.0, n_blocks=10**6,
                      n_effective=10**6, threshold=cusum_threshold(arl), arl_blocks=arl)
    lengths = []
    for _ in range(600):
        det = Detector(DetectionSettings())
        det.start(cal)
        k = 0
        while True:
            k += 1
            test = det.statistic(float(rng.standard_normal()))
            if det.step(0.1 * k, np.array([0.0, 0.0, 0.0, test])) == "alarm":
                break
        lengths.append(k)
    # standard error ≈ 200/√600 = 4 %; the approximation a few %: 15 %
    assert np.mean(lengths) == pytest.approx(arl, rel=0.15)


def test_calibration_bounds_cover_the_true_values():
    # 97.5 % one-sided bounds of μ and σ from 75 independent Gaussian blocks: over 600
    # learning times, the fraction covered is binomial (sd 0.6 %)
    rng = np.random.default_rng(5)
    covered_mean = covered_sd = 0
    for _ in range(600):
        cal = calibrate(2.0 + 0.3 * rng.standard_normal(75), arl_blocks=1e5)
        covered_mean += cal.mean >= 2.0
        covered_sd += cal.sd >= 0.3
    assert 0.95 <= covered_mean / 600 <= 0.995
    assert 0.95 <= covered_sd / 600 <= 0.995


def test_calibration_counts_correlated_blocks_as_fewer():
    # AR(1) blocks, ρ = 0.5: the long-run variance is s² (1 + ρ)/(1 − ρ) = 3 s², and
    # 4000 blocks are worth 4000/3 independent ones; ρ̂ has a standard error of
    # √((1 − ρ²)/n) = 0.014, which moves the factor 3 by 2/(1 − ρ)² · 0.014 = 0.11
    rng = np.random.default_rng(9)
    e = rng.standard_normal(4000)
    x = lfilter([1.0], [1.0, -0.5], e)
    cal = calibrate(x, arl_blocks=1e5)
    assert cal.n_blocks / cal.n_effective == pytest.approx(3.0, abs=0.4)
    assert cal.sd_hat**2 / np.var(x, ddof=1) == pytest.approx(3.0, abs=0.4)


def test_too_few_blocks_are_refused():
    with pytest.raises(ParameterError, match="too few"):
        calibrate(np.array([1.0, 2.0, 1.5]), arl_blocks=100.0)
    with pytest.raises(ParameterError, match="do not vary"):
        calibrate(np.ones(50), arl_blocks=100.0)


def test_alarm_clears_once_the_test_stays_below_half_for_clear_s():
    det = Detector(DetectionSettings(clear_s=0.3))
    det.start(Calibration(mean=0.0, sd=1.0, mean_hat=0.0, sd_hat=1.0, n_blocks=100,
                          n_effective=100.0, threshold=5.0, arl_blocks=1e3))
    fig = np.zeros(3)

    def step(t, x):
        return det.step(t, np.append(fig, det.statistic(x)))

    assert step(0.1, 0.0) is None
    assert step(0.2, 20.0) == "alarm"          # S = 19.5 ≥ 5, held at 5
    assert step(0.3, 20.0) is None             # stays on
    # back to normal: S falls by κ = 0.5 a block, 4.5, 4.0, …, below h/2 = 2.5 at
    # t = 0.9 (S = 2.0), and clears 0.3 s later
    kinds = [step(round(0.4 + 0.1 * k, 1), 0.0) for k in range(9)]
    assert kinds == [None] * 8 + ["clear"]


def test_a_figure_gate_holds_back_an_alarm_of_the_test():
    det = Detector(DetectionSettings(frf_db=1.0))
    det.start(Calibration(mean=0.0, sd=1.0, mean_hat=0.0, sd_hat=1.0, n_blocks=100,
                          n_effective=100.0, threshold=5.0, arl_blocks=1e3))
    assert det.step(0.1, np.array([0.5, 0, 0, det.statistic(20.0)])) is None
    out = det.step(0.2, np.array([1.5, 0, 0, det.statistic(20.0)]))
    assert out == "alarm" and det.exceeded(np.array([1.5, 0, 0, 4.0])) == ["frf_db", "test"]


def test_recent_mode_flags_a_step_and_forgets_it():
    # two-sided on x_k − x_{k−R}: a step of 20 σ at block 10 is flagged there (S held
    # at h = 5); once R = 5 blocks have passed the difference is 0 again and S falls by
    # κ = 0.5 a block, below h/2 at block 20, and clears 0.2 s later
    det = Detector(DetectionSettings(compare="recent", clear_s=0.2))
    det.start(Calibration(mean=0.0, sd=1.0, mean_hat=0.0, sd_hat=1.0, n_blocks=100,
                          n_effective=100.0, threshold=5.0, arl_blocks=1e3), lag_blocks=5)
    kinds = []
    for k in range(30):
        x = 0.0 if k < 10 else 20.0
        kinds.append(det.step(0.1 * k, np.array([0, 0, 0, det.statistic(x)])))
    assert kinds.index("alarm") == 10
    assert kinds.index("clear") == 22
    assert kinds.count("alarm") == 1


def test_either_predictor_raises_the_alarm_and_a_level_must_explain_both():
    cal = Calibration(mean=0.0, sd=1.0, mean_hat=0.0, sd_hat=1.0, n_blocks=100,
                      n_effective=100.0, threshold=5.0, arl_blocks=1e3)
    det = Detector(DetectionSettings())
    det.start([cal, cal])
    # the second predictor alone rises: an alarm; S/h is the larger of the two
    assert det.statistic([0.0, 0.0]) == 0.0
    assert det.statistic([0.0, 3.0]) == pytest.approx(2.5 / 5.0)
    assert det.step(0.2, np.array([0, 0, 0, det.statistic([0.0, 20.0])])) == "alarm"
    # a rise of the reference's level explains it only where it explains every test
    # at its threshold: with the levels, a rise at a new level is a new level
    det = Detector(DetectionSettings())
    det.start([cal, cal], levels=np.zeros(20) + 0.01 * np.arange(20))
    assert det.step(0.1, np.array([0, 0, 0, det.statistic([20.0, 20.0], level=5.0)])) \
        == "level"
    # the first test rose over three blocks at the learnt level, the second at the
    # last block, 1.0 above it: the last four levels (h/(2 − κ) = 4) of the first are
    # 0.15 above the learnt ones, within its drift (0.5 σ); the second's, 0.9
    det = Detector(DetectionSettings())
    det.start([cal, cal], levels=np.zeros(20) + 0.01 * np.arange(20))
    for _ in range(3):
        det.statistic([20.0, 0.0], level=0.0)
    assert det.step(0.2, np.array([0, 0, 0, det.statistic([20.0, 20.0], level=1.0)])) \
        == "alarm"


# ---------------------------------------------------------------- prediction errors
def test_prediction_errors_of_the_true_model_are_its_noise():
    # y from A y = q^{-1} B u + C e, all from rest: the filter returns e exactly (to
    # rounding: three filters of order 2 on values of order 1, 1e-12), block after block
    rng = np.random.default_rng(2)
    a, b, c = np.array([1, -1.5, 0.7]), np.array([0.5, 0.3]), np.array([1, 0.4, 0.2])
    u, e = rng.standard_normal(2000), 0.1 * rng.standard_normal(2000)
    y = lfilter(np.r_[0.0, b], a, u) + lfilter(c, a, e)
    res = BaselineResidual(a, b, c, 1)
    eps = np.concatenate([res(u[i:j], y[i:j]) for i, j in ((0, 7), (7, 700), (700, 2000))])
    np.testing.assert_allclose(eps, e, atol=1e-12)


def test_a_noise_model_with_a_root_outside_is_reflected_inside():
    # C = 1 + 2 q⁻¹ (root at −2): 1/C would diverge; 1 + 0.5 q⁻¹ has the same spectrum
    # up to the gain 4, so ε = (C/C') e is white with variance 4 σ²: its lag-1
    # correlation is 0 within 4/√n = 0.03 for n = 20000
    rng = np.random.default_rng(4)
    e = rng.standard_normal(20000)
    y = lfilter([1.0, 2.0], [1.0], e)                 # A = 1, B = 0
    eps = BaselineResidual(np.array([1.0]), np.array([0.0]), np.array([1.0, 2.0]), 1)(
        np.zeros_like(y), y)
    assert np.all(np.isfinite(eps))
    assert abs(np.corrcoef(eps[:-1], eps[1:])[0, 1]) < 0.03
    assert np.var(eps) == pytest.approx(4.0, rel=0.05)   # χ² of 20000: sd 1 %


def test_block_statistic_is_the_log_median_of_squares():
    assert block_statistic(np.array([1.0, -2.0, 3.0])) == pytest.approx(math.log(4.0))
    assert math.isnan(block_statistic(np.zeros(5)))
    assert math.isnan(block_statistic(np.empty(0)))


@pytest.mark.parametrize(("a", "b", "word"), [
    ([1.0, -2.1, 1.1], [1.0], "unstable"),           # poles 1.1 and 1.0
    ([1.0, -0.5], [1e300], r"coefficient of 1e\+300"),
])
def test_a_baseline_that_cannot_be_a_running_loop_is_refused(a, b, word):
    model = ehss.ArmaxModel(a=np.array(a), b=np.array(b), c=np.array([1.0]), delay=1,
                            dt=1e-3)
    with pytest.raises(ParameterError, match=word):
        check_baseline(model)


def test_after_samples_lost_the_predictor_gives_no_error_until_its_start_has_died_out():
    # an output-error filter (C = A, poles at radius 0.95) of the exact model on
    # noise-free data: ε = 0. 100 samples lost: carried on, its state is that of the
    # samples before and ε rings for tens of samples; restarted, its history is filled
    # from the samples that come, no error is given over its settling time (its
    # history and 7 time constants of 0.95: 2 + ⌈7/0.0513⌉ = 139 samples), and then ε is
    # 0 again
    rng = np.random.default_rng(3)
    a, b = np.array([1.0, -1.6, 0.9025]), np.array([0.2, 0.1])
    u = rng.standard_normal(3000)
    y = lfilter(np.r_[0.0, b], a, u)
    keep = np.r_[0:1000, 1100:3000]
    carried = BaselineResidual(a, b, a, 1)
    restarted = BaselineResidual(a, b, a, 1)
    assert restarted.settle == 2 + math.ceil(7.0 / -math.log(0.95))
    for res in (carried, restarted):
        np.testing.assert_allclose(res(u[:1000], y[:1000]), 0.0, atol=1e-12)
    restarted.restart()
    eps_c = carried(u[keep[1000:]], y[keep[1000:]])
    eps_r = restarted(u[keep[1000:]], y[keep[1000:]])
    assert np.max(np.abs(eps_c[:50])) > 0.1 * np.std(y)       # the jump rings on
    assert np.all(np.isnan(eps_r[:restarted.settle]))
    np.testing.assert_allclose(eps_r[restarted.settle:], 0.0, atol=1e-9 * np.std(y))


def test_whitening_filter_of_an_autoregression_is_its_polynomial():
    # AR(2) with poles 0.9 and 0.5: D = 1 − 1.4 q⁻¹ + 0.45 q⁻²; Yule–Walker on 10⁵
    # samples, standard error of the coefficients about √((1 − 0.45²)/n) < 0.003
    e = np.random.default_rng(6).standard_normal(100_000)
    v = lfilter([1.0], [1.0, -1.4, 0.45], e)
    np.testing.assert_allclose(whitening_filter(v, 2), [1.0, -1.4, 0.45], atol=0.01)
    with pytest.raises(ParameterError, match="do not vary"):
        whitening_filter(np.zeros(100), 2)


def test_the_output_error_predictor_of_a_loop_is_its_sensor_noise():
    # y = q^-1 B/F u + white noise, a baseline off by 10 % in its gain and with a C far
    # from its A: the refit finds B/F, its output errors are the noise (whitening leaves
    # white noise white: its AR coefficients are O(1/√n)), ε₂ ≈ e to well under the
    # noise's 1 % level of the output
    rng = np.random.default_rng(8)
    f, b = np.array([1.0, -1.6, 0.9025]), np.array([0.2, 0.1])
    u = rng.standard_normal(20_000)
    clean = lfilter(np.r_[0.0, b], f, u)
    e = 0.01 * np.std(clean) * rng.standard_normal(u.size)
    base = ehss.ArmaxModel(a=f, b=1.1 * b, c=[1.0, -0.5, 0.0], delay=1)
    eps = output_error_predictor(base, u, clean + e)(u, clean + e)
    # the difference: the refit's and D's estimation errors on e, O(1/√n) each
    # (about 0.03 σ of e here)
    assert np.sqrt(np.mean((eps[1000:] - e[1000:]) ** 2)) < 0.1 * np.std(e)


def test_refits_take_turns_of_the_join_time():
    from ehss.live.channel import RefitTurns

    turns = RefitTurns()
    # three channels whose tests start together join one turn after another
    assert [turns.join_at(100, 20) for _ in range(3)] == [120, 140, 160]
    # one that starts after the turns booked so far joins a turn after its own start
    assert turns.join_at(300, 20) == 320
    # one that starts within the last turn waits for it
    assert turns.join_at(310, 20) == 340
