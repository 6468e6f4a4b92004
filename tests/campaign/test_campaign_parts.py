"""The parts of a campaign against analytic answers: loop figures, the outlier rule,
the parameter sampling, task seeds."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.stats import norm

from ehss.campaign.demo import RigHealthYear
from ehss.campaign.engine import Task, task_seed
from ehss.campaign.figures import loop_figures
from ehss.campaign.montecarlo import (
    Distribution,
    MonteCarloSettings,
    _distribution,
    acceptance_fraction,
    draw_samples,
)
from ehss.campaign.outliers import OutlierRule, flag_outliers, robust_z
from ehss.errors import ParameterError
from ehss.identification import ArmaxModel


def second_order(fn_hz: float, zeta: float, dt: float) -> ArmaxModel:
    """Poles of s² + 2ζωn s + ωn² mapped exactly (z = e^{s dt}), unit DC gain, delay 1."""
    wn = 2 * math.pi * fn_hz
    s = -zeta * wn + 1j * wn * math.sqrt(1 - zeta**2)
    a = np.real(np.poly([np.exp(s * dt), np.exp(np.conj(s) * dt)]))
    return ArmaxModel(a=a, b=np.array([a.sum()]), delay=1, dt=dt)


def test_dominant_poles_of_a_known_loop():
    m = second_order(20.0, 0.3, 1e-3)
    f = loop_figures(m)
    # exact pole mapping: ln(z)/dt gives s back to rounding (1e-12 relative)
    assert_allclose(f["natural_freq_hz"], 20.0, rtol=1e-10)
    assert_allclose(f["damping"], 0.3, rtol=1e-10)
    assert_allclose(f["dc_gain"], 1.0, rtol=1e-12)
    assert f["delay_s"] == 1e-3


def test_bandwidth_of_a_first_order_loop():
    a, dt = 0.9, 1e-3
    m = ArmaxModel(a=np.array([1.0, -a]), b=np.array([1 - a]), delay=1, dt=dt)
    # |G|² = (1-a)² / (1 - 2a cos w + a²) = 1/2  <=>  cos w = 1 - (1-a)²/(2a)
    w = math.acos(1 - (1 - a) ** 2 / (2 * a))
    # linear interpolation on a 4096-point grid to fs/2: error far below 1e-4 relative
    assert_allclose(loop_figures(m)["bandwidth_hz"], w / (2 * math.pi * dt), rtol=1e-4)
    assert math.isnan(loop_figures(m)["natural_freq_hz"]) is False  # a real pole: ζ = 1
    assert loop_figures(m)["damping"] == pytest.approx(1.0)


def test_threshold_is_bonferroni_normal_quantile():
    rule = OutlierRule(alpha=0.01)
    assert rule.threshold(5) == pytest.approx(norm.isf(0.01 / 10), rel=1e-12)


def test_false_flag_rate_under_normality():
    """Sound records (normal scatter about a slow drift) are flagged at about the stated
    rate: binomial bounds on 4000 records."""
    rng = np.random.default_rng(3)
    n, alpha = 4000, 0.05
    x = np.linspace(30.0, 25.0, n) + 0.2 * rng.standard_normal(n)
    flags, _, _ = flag_outliers({"natural_freq_hz": x}, OutlierRule(alpha=alpha, window=31))
    # 99.9 % binomial interval of the count; the residual from a running median is a
    # little narrower than the scatter, and the MAD rescales it, so the rate stays alpha
    lo, hi = (norm.ppf([0.0005, 0.9995]) * math.sqrt(n * alpha * (1 - alpha)) + n * alpha)
    assert lo <= flags.sum() <= hi


def test_drift_is_a_trend_and_a_fault_is_flagged():
    rng = np.random.default_rng(0)
    n, alpha = 365, 0.01
    x = np.linspace(32.0, 26.0, n) + 0.05 * rng.standard_normal(n)  # slow loss
    x[200] -= 1.0  # one bad day: 20 sigma
    flags, why, z = flag_outliers({"natural_freq_hz": x}, OutlierRule(alpha=alpha))
    assert flags[200] and "natural_freq_hz" in why[200]
    # the drift itself is not flagged: the other flags are the stated false-flag rate's
    # (99.9 % binomial upper bound of n·alpha)
    others = flags.sum() - 1
    assert others <= n * alpha + norm.ppf(0.999) * math.sqrt(n * alpha * (1 - alpha))


def test_robust_z_needs_enough_records_and_spread():
    z, _, _ = robust_z(np.array([1.0, 2.0, 3.0]), 15)
    assert np.isnan(z).all()
    z, _, sigma = robust_z(np.ones(40), 15)
    assert np.isnan(z).all() and sigma == 0


def test_task_seeds_follow_the_key_only():
    a = np.random.default_rng(task_seed(7, "r1")).random(3)
    assert_allclose(np.random.default_rng(task_seed(7, "r1")).random(3), a, rtol=0)
    assert not np.allclose(np.random.default_rng(task_seed(7, "r2")).random(3), a)
    assert not np.allclose(np.random.default_rng(task_seed(8, "r1")).random(3), a)
    with pytest.raises(ParameterError, match="task key"):
        Task("../escape")


def settings(n: int, sampling: str = "sobol") -> MonteCarloSettings:
    return MonteCarloSettings(samples=n, sampling=sampling, seed=3, parameters=(
        Distribution(name="load.mass_kg", kind="uniform", a=200.0, b=300.0),
        Distribution(name="actuator.bulk_modulus_pa", kind="normal", a=6.9e8, b=0.5e8),
        Distribution(name="valve.rated_flow_m3_s", kind="lognormal", a=6e-4, b=0.1)))


@pytest.mark.parametrize("sampling", ["sobol", "lhs"])
def test_samples_are_reproducible_and_follow_their_distributions(sampling):
    x = draw_samples(settings(512, sampling))
    assert_allclose(draw_samples(settings(512, sampling)), x, rtol=0)
    assert ((x[:, 0] >= 200) & (x[:, 0] <= 300)).all()
    # quasi-random points match the distributions' moments far better than 1/sqrt(n):
    # 1 % of sigma for the mean is loose for 512 stratified points
    assert abs(x[:, 1].mean() - 6.9e8) < 0.01 * 0.5e8 * 5
    assert_allclose(np.median(np.log(x[:, 2])), math.log(6e-4), atol=0.02)


def test_sobol_draw_is_a_prefix():
    """N samples are the first N of a longer draw: growing a campaign keeps its samples."""
    assert_allclose(draw_samples(settings(5)), draw_samples(settings(16))[:5], rtol=0)


def test_distribution_forms():
    from ehss.params import preset

    p = preset("default")
    d = _distribution("load.mass_kg", {"distribution": "uniform", "rel": 0.2}, p)
    assert (d.a, d.b) == pytest.approx((0.8 * p.load.mass_kg, 1.2 * p.load.mass_kg))
    with pytest.raises(ParameterError, match="unknown rig parameter 'load.weight'"):
        _distribution("load.weight", {"distribution": "uniform", "rel": 0.2}, p)
    with pytest.raises(ParameterError, match="'normal' takes mean, std"):
        _distribution("load.mass_kg", {"distribution": "normal", "rel": 0.2}, p)


def test_acceptance_fraction_with_its_interval():
    import polars as pl

    frame = pl.DataFrame({"status": ["ok"] * 10,
                          "error_uncompensated_pct": [100.0] * 10,
                          "error_nominal_pct": [10.0] * 7 + [80.0] * 3})
    out = acceptance_fraction(frame, settings(10))
    assert out["k"] == 7 and out["fraction"] == 0.7
    # Clopper-Pearson 95 % for 7/10: (0.3475, 0.9333) from the beta quantiles
    assert_allclose(out["ci95"], (0.34754, 0.93326), atol=1e-4)


def test_a_tasks_rows_supersede_an_error_row_of_the_same_key(tmp_path):
    # a task whose worker was lost runs again elsewhere; the client may have recorded
    # the first run as failed while the second finished: one row, the finished one
    import polars as pl

    from ehss.campaign.engine import TASKS_FOLDER, read_results

    folder = tmp_path / TASKS_FOLDER
    folder.mkdir()
    pl.DataFrame({"task": ["a"], "status": ["ok"], "error": [""]}).write_parquet(
        folder / "a.parquet")
    pl.DataFrame({"task": ["a"], "status": ["error"], "error": ["KilledWorker"]}
                 ).write_parquet(folder / "a.error.parquet")
    pl.DataFrame({"task": ["b"], "status": ["error"], "error": ["no such file"]}
                 ).write_parquet(folder / "b.error.parquet")
    rows = read_results(tmp_path)
    assert rows.select("task", "status").rows() == [("a", "ok"), ("b", "error")]


def test_the_trend_plot_is_a_png_of_its_own(tmp_path):
    # forty daily records of a drifting loop with one fault: the plot is written whole
    import datetime as dt

    import polars as pl

    from ehss.campaign.summary import flag_campaign, write_trend_png

    n = 40
    days = [dt.datetime(2026, 1, 1, tzinfo=dt.UTC) + dt.timedelta(days=k) for k in range(n)]
    wn = np.linspace(28.0, 24.0, n) + 0.01 * np.random.default_rng(3).standard_normal(n)
    wn[25] = 27.5
    frame = pl.DataFrame({"record": [f"day{k}" for k in range(n)], "channel": ["1"] * n,
                          "status": ["ok"] * n, "record_time": days, "natural_freq_hz": wn,
                          "damping": np.full(n, 0.23), "dc_gain": np.full(n, 1.05),
                          "bandwidth_hz": wn + 1.0, "fit_pct": np.full(n, 97.0)})
    flagged = flag_campaign(frame, OutlierRule())
    assert flagged["flagged"].to_list()[25]
    path = write_trend_png(flagged, tmp_path / "trend.png", OutlierRule())
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize(("field", "value", "error"), [
    ("days", 0, ParameterError),
    ("days", 3.0, TypeError),
    ("duration_s", 0.0, ParameterError),
    ("bulk_modulus_loss", 1.0, ParameterError),
    ("fault_day", -1, ParameterError),
    ("fault_flow_factor", 0.0, ParameterError),
    ("rms_m", float("nan"), ParameterError),
    ("start", "first of January", ParameterError),
])
def test_a_rig_health_year_refuses_a_bad_field_by_name(field, value, error):
    with pytest.raises(error, match=field):
        RigHealthYear(**{field: value})


def test_a_rig_health_year_keeps_its_fields_as_given():
    year = RigHealthYear(days=2, duration_s=1.5, fault_day=400)  # no fault in the year
    assert (year.days, year.duration_s, year.fault_day) == (2, 1.5, 400)
    assert year == RigHealthYear(days=2, duration_s=1.5, fault_day=400)


@pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning")
def test_ctrl_c_swallowed_by_a_destructor_still_stops_the_campaign():
    # Dask releases futures (Future.__del__) in the loop that collects results; Python
    # ignores an exception raised in a destructor, so a Ctrl-C landing there is lost
    # unless it is recorded as well.
    import os
    import signal
    import time

    from ehss.campaign import engine

    class Releases:
        def __del__(self):
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.05)  # the handler runs here; its KeyboardInterrupt is ignored

    # what ran before is given back: Python's default, or SIG_IGN when the suite runs as
    # a background job of a shell (nohup, `make test &`)
    before = signal.getsignal(signal.SIGINT)
    with engine._Interrupt() as interrupt:
        interrupt.check()  # nothing yet
        obj = Releases()
        del obj  # the interrupt is swallowed by the destructor
        with pytest.raises(KeyboardInterrupt):
            interrupt.check()
    assert signal.getsignal(signal.SIGINT) is before
