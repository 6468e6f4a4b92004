"""Adaptive compensation with its default settings on loops that are not the simulated
rig (``stepping_loops.py``: two channels, 1 % sensor noise, the band taken from the
reference): the 25 Hz servo at 2 kHz after +40 % moving mass, and the actuator on its
specimen at 4 kHz after +40 % specimen stiffness, on channel 1 at t = 20 s. The figures
asserted and their spread over other references are in docs/adaptive_compensation.md ("On loops
that are not the rig")."""

from __future__ import annotations

import math

import numpy as np
import pytest
from held_inverse import Sending, held
from stepping_loops import (
    DELAYED,
    HIGH_PASS,
    LAGGED,
    OIL_COLUMN,
    SERVO,
    SPECIMEN,
    SteppingLoop,
    loop_desired,
)

from ehss.live.compensate import AdaptiveLoop, CompensationRecord, CompensationSettings

CHANGE_S = 20.0
DURATION_S = 30.0

#: Each case: the loop, the reference's band (flat, nothing outside; the band the
#: compensation works over is found from it), the factor of the parameter that changes,
#: the bounds of channel 1's error against its level before over [22, 24) s and over
#: each later 2-s stretch, and the run's length. Measured on four pairs of references
#: (seeds 1-8, README): the servo's change raises its error 20-36x, and the model
#: refitted on the rows since it brings [22, 24) s to 1.01-1.18x, later stretches within
#: 1.04x; the specimen 0.87-1.09x and 0.80-1.04x. On seeds 1, 2 with the sensor noise's
#: seeds 0-5, on another machine than those figures' (its rounding takes a run another
#: course, as the noise does): servo 0.97-1.03x / <= 1.03x, specimen 1.07-1.20x /
#: <= 1.01x, delayed loop 1.03-1.17x / <= 1.09x, frozen >= 10.7x, every change flagged
#: at 20.1-20.2 s. All three are held to the aim, 1.5x from 2 s after the change (before
#: the refit the servo was 1.7-3.1x over [22, 24) s and held to 4x: README).
CASES = {
    "servo 2 kHz, +40 % mass": (SERVO, (1.0, 50.0), 1.4, 1.5, 1.5, DURATION_S),
    "specimen 4 kHz, +40 % stiffness": (SPECIMEN, (1.0, 40.0), 1.4, 1.5, 1.5, DURATION_S),
    # the 12 Hz loop behind 2 ms of delay: its error rises 20-25x; the first model
    # refitted since the change (0.8-1 s of rows) is in 1.5 s after it
    "delayed 1 kHz, +40 % mass": (DELAYED, (0.5, 20.0), 1.4, 1.5, 1.5, DURATION_S),
    # the 15 Hz loop whose 40 Hz, zeta 0.15 oil-column mode sits at the band's top: the
    # refits from the recursive estimate stop in a local minimum there, the refit from
    # the data alone does not. +40 % mass moves the mode to 34 Hz, inside the band: the
    # models after the change fit their windows by 98.5-99 %, but the target's filter
    # realises their inverses to 0.9-5 % of the reference, and loaded one after the
    # other (each by its own account of the compensator that ran, which holds its own
    # change of model) they took the error from 1.2x its level before to 2-5.5x from
    # 24 s on over 40 s. A design that by its model's account leaves no less than the
    # running one is now kept out: later stretches within 1.03-1.34x on four pairs
    # (40 s). Its first models after the change scatter more than the other loops':
    # [22, 24) s at 1.15-1.79x (1.79x on these references; README)
    "oil column 2 kHz, +40 % mass": (OIL_COLUMN, (1.0, 40.0), 1.4, 2.0, 1.5, 40.0),
}


def _run(target: SteppingLoop, adapt_until_s: float = math.inf) -> CompensationRecord:
    return AdaptiveLoop(target, CompensationSettings(adapt_until_s=adapt_until_s)).run()


@pytest.mark.slow
@pytest.mark.parametrize("case", list(CASES))
def test_adaptation_follows_a_change_of_another_loop(case: str) -> None:
    spec, ref_band, factor, first_bound, later_bound, duration_s = CASES[case]
    desired = loop_desired(spec, duration_s, (1, 2), band_hz=ref_band)
    windows = [(t, t + 2.0) for t in np.arange(CHANGE_S + 2.0, duration_s, 2.0)]

    def target() -> SteppingLoop:
        return SteppingLoop(spec, desired, preview=128, seed=0, change_s=CHANGE_S,
                            factor=factor)

    sending = Sending(target())
    adapted = _run(sending)
    frozen = held(target, sending.sent, CHANGE_S)   # the inverse of before, not adapted
    # up to the change the held run is the adapted run again
    np.testing.assert_array_equal(frozen.feedback[:, :int(CHANGE_S * spec.fs)],
                                  adapted.feedback[:, :int(CHANGE_S * spec.fs)])
    plain = target().step(desired.shape[1])                  # no compensation
    fs = spec.fs
    err = (plain.desired - plain.feedback)[:, int(10 * fs):int(CHANGE_S * fs)]
    uncompensated = np.sqrt(np.mean(err**2, axis=1))

    before = adapted.tracking_rms(10.0, CHANGE_S)
    # steady state: at least 20 times less error than without compensation (measured
    # 109-129x on the servo, 46-51x on the specimen, 117-127x on the oil column over 40 s)
    assert np.all(before <= uncompensated / 20.0)
    # the change is flagged on channel 1 within 0.75 s (0.1-0.2 s measured), and not on
    # channel 2 after it
    changes = [(e["channel"], e["t_s"]) for e in adapted.events
               if e["kind"] == "compensator_change" and e["t_s"] > CHANGE_S]
    assert changes and changes[0][0] == "1" and changes[0][1] <= CHANGE_S + 0.75
    assert all(c[0] == "1" for c in changes)
    # a change of a healthy loop is followed, not alarmed (in steady running before it
    # the servo raises a false alarm now and then: README)
    assert not [e for e in adapted.events if e["kind"] == "alarm" and e["t_s"] >= CHANGE_S]
    after = [adapted.tracking_rms(*w) for w in windows]
    assert after[0][0] <= first_bound * before[0]
    for a in after[1:]:
        assert a[0] <= later_bound * before[0]
    # the inverse of before the change, not adapted, at least 2x worse in every stretch
    # (measured 12-42x on these references)
    for w, a in zip(windows, after, strict=True):
        assert frozen.tracking_rms(*w)[0] >= 2.0 * a[0], w
    # channel 2 does not change: within the scatter of 1-s stretches before (+-30 %;
    # measured 0.93-1.06x)
    assert adapted.tracking_rms(CHANGE_S + 2.0, duration_s)[1] <= 1.3 * before[1]
    assert adapted.loads and all(load["accepted"] for load in adapted.loads)



def test_a_preview_too_short_for_the_loop_at_its_rate_is_said() -> None:
    # the servo's group delay at low frequencies is 2ζ/ω summed over its valve and its
    # mode, 2.8 + 5.1 = 7.9 ms: 16 samples at 2 kHz. A target that reads 16 samples
    # ahead (8 ms) holds no more of its inverse than that delay: its compensators miss
    # the H1 bounds (2.8 dB / 7°) but still track far better than none, so they are
    # loaded, each saying how far ahead the target reads; 128 (64 ms) hold it all
    desired = loop_desired(SERVO, 5.0, (1,), band_hz=(1.0, 50.0))
    runs = {pv: AdaptiveLoop(SteppingLoop(SERVO, desired, preview=pv, seed=0),
                             CompensationSettings(adapt_until_s=adapt)).run()
            for pv, adapt in ((16, np.inf), (128, np.inf), (0, 0.0))}
    none = runs[0].tracking_rms(3.0, 5.0)[0]
    assert runs[16].loads and runs[128].loads and not runs[0].loads
    assert all("16 samples ahead (8 ms at 2000 Hz)" in ld["realisation"]
               for ld in runs[16].loads)
    assert not any("realisation" in ld for ld in runs[128].loads)
    # measured: 1384 µm without, 187 µm with 16 samples ahead, 11 µm with 128
    assert runs[128].tracking_rms(3.0, 5.0)[0] < runs[16].tracking_rms(3.0, 5.0)[0] < none / 3


def _change_at_a_load() -> tuple[dict, float, CompensationRecord]:
    """The servo's moving mass +40 % on channel 1 at the sample where its first load
    from 12 s on begins to fade in (found in the same run without the change, the same
    up to it): that load, the time of the change and the run."""
    desired = loop_desired(SERVO, 18.0, (1, 2), band_hz=(1.0, 50.0))
    steady = AdaptiveLoop(SteppingLoop(SERVO, desired, preview=128, seed=0),
                          CompensationSettings()).run(duration_s=14.0)
    load = next(ld for ld in steady.loads
                if ld["channel"] == "1" and ld["t_s"] >= 12.0 and ld["model"] != "rollback")
    change_s = load["apply_index"] / SERVO.fs
    rec = _run(SteppingLoop(SERVO, desired, preview=128, seed=0, change_s=change_s,
                            factor=1.4))
    assert any(ld["apply_index"] == load["apply_index"] for ld in rec.loads)
    return load, change_s, rec


def _followed(rec: CompensationRecord, change_s: float, within_s: float) -> dict:
    """The one change flagged, on channel 1 within ``within_s`` of ``change_s``, followed
    by a correction, or a model refitted on rows since the change, and no alarm."""
    changes = [e for e in rec.events if e["kind"] == "compensator_change"]
    assert len(changes) == 1 and changes[0]["channel"] == "1"
    assert change_s < changes[0]["t_s"] <= change_s + within_s
    after = [ld for ld in rec.loads if ld["channel"] == "1" and ld["t_s"] > changes[0]["t_s"]]
    assert after[0]["model"] == "correction" \
        or 0 < after[0].get("refit_rows", 0) <= (after[0]["t_s"] - change_s) * SERVO.fs
    assert not [e for e in rec.events if e["kind"] == "alarm"]
    return changes[0]


@pytest.mark.slow
def test_a_change_as_a_load_fades_in_is_followed_at_once() -> None:
    # the change raises the servo's error 20-35x at once, dated to the load; the model
    # the compensator before it was designed from matches the feedback as badly as the
    # compensator tracks (a worse compensator would leave its output errors where they
    # were), so the change is followed, not undone, within 0.75 s as any change
    load, change_s, rec = _change_at_a_load()
    assert _followed(rec, change_s, 0.75)["at_load"] == load["apply_index"]
    assert not [e for e in rec.events
                if e["kind"] == "compensator_rollback" and e["t_s"] > change_s]


@pytest.mark.slow
def test_a_change_taken_for_a_load_is_still_followed(monkeypatch: pytest.MonkeyPatch
                                                     ) -> None:
    # were the output errors to miss the change, the load is undone (the compensator
    # before it sent again), and the trigger, which tests on against the level it had
    # learnt, flags the error still high once that one has faded in: within 1.5 s
    from ehss.live.compensate import ChannelAdapter

    monkeypatch.setattr(ChannelAdapter, "_loop_unchanged", lambda *args: True)
    load, change_s, rec = _change_at_a_load()
    rollbacks = [e for e in rec.events
                 if e["kind"] == "compensator_rollback" and e["t_s"] > change_s]
    assert len(rollbacks) == 1 and rollbacks[0]["loaded_index"] == load["apply_index"]
    change = _followed(rec, change_s, 1.5)
    assert change["t_s"] > (rollbacks[0]["apply_index"] + rollbacks[0]["crossfade"]) / SERVO.fs


def test_the_refit_follows_the_stream_it_is_for() -> None:
    # by default the models are refitted while channels x rate leaves the worker its
    # share of a core (REFINE_LOAD); a setting given stays; the record says which
    from ehss.live.compensate.settings import REFINE_LOAD

    auto = CompensationSettings()
    assert auto.refine is None
    assert auto.for_stream(2, 1000.0).refine is True
    assert auto.for_stream(8, 5000.0).refine is False
    assert auto.for_stream(1, REFINE_LOAD).refine is True
    assert auto.for_stream(1, REFINE_LOAD + 1.0).refine is False
    forced = CompensationSettings(refine=True, n_taps=300)
    assert forced.for_stream(8, 5000.0) is forced
    assert auto.for_stream(8, 5000.0).to_dict()["refine"] is False
    # a window twice as long (a narrow band) has twice the rows to refit
    long = auto.for_band((0.5, 8.5))
    assert long.h1_window_s == pytest.approx(3.0)
    assert long.for_stream(1, REFINE_LOAD / 2).refine is True
    assert long.for_stream(1, REFINE_LOAD / 2 + 1.0).refine is False


def test_the_fir_spans_the_same_time_at_any_rate() -> None:
    # what the FIR realises is set in hertz (the band limit's transitions), so its taps
    # follow the rate: 0.256 s of them, at least twice the target's preview, at most
    # the target's capacity; a length given stays
    from ehss.compensation.compensator_design import FIR_SPAN_S, design_compensator
    from ehss.errors import ParameterError
    from ehss.identification.model import ArmaxModel
    from ehss.target.filter import MAX_TAPS

    auto = CompensationSettings()
    assert auto.n_taps is None
    assert auto.for_stream(2, 1000.0).n_taps == 256
    assert auto.for_stream(8, 5000.0).n_taps == math.ceil(FIR_SPAN_S * 5000.0) == 1280
    assert auto.for_stream(1, 500.0, preview=128).n_taps == 256
    assert auto.for_stream(1, 1e5).n_taps == MAX_TAPS
    assert CompensationSettings(n_taps=300).for_stream(8, 5000.0).n_taps == 300
    assert auto.for_stream(8, 5000.0).to_dict()["n_taps"] == 1280
    with pytest.raises(ParameterError, match="n_taps"):
        CompensationSettings(n_taps=MAX_TAPS + 1)
    # a first-order loop at 5 kHz over 1-50 Hz: the span it asks is the one the same
    # loop asks at 1 kHz (its pole at the same time constant), and 256 taps, a fifth of
    # it, realise its inverse far worse
    errors = {}
    for fs, n_taps in ((1000.0, 256), (5000.0, 1280), (5000.0, 256)):
        m = ArmaxModel(a=[1.0, -math.exp(-2 * math.pi * 30.0 / fs)],
                       b=[1.0 - math.exp(-2 * math.pi * 30.0 / fs)], delay=1, dt=1 / fs)
        errors[fs, n_taps] = design_compensator(m, band_hz=(1.0, 50.0), n_taps=n_taps) \
            .errors()["rms_relative_error"]
        if n_taps != 256 or fs == 1000.0:
            assert design_compensator(m, band_hz=(1.0, 50.0)).taps.size == n_taps
    assert errors[5000.0, 1280] < 2 * errors[1000.0, 256]
    assert errors[5000.0, 256] > 5 * errors[5000.0, 1280]


def test_a_bad_refit_setting_is_refused() -> None:
    from ehss.errors import ParameterError

    with pytest.raises(ParameterError, match="refine='no' must be True, False or None"):
        CompensationSettings(refine="no")  # type: ignore[arg-type]


def test_a_model_is_refitted_to_the_errors_its_inverse_will_leave() -> None:
    # a known fourth-order loop (resonance at 15 Hz, zeta 0.3), a 0.5-20 Hz drive cut
    # out of a running test, 1 % sensor noise; a start 3 % off in gain
    import scipy.signal

    import ehss
    from ehss.compensation.adaptive import AdaptiveCompensator
    from ehss.live.compensate import Judging

    fs, band = 1000.0, (0.5, 20.0)
    w, z = 2 * math.pi * 15.0, 0.3
    p = np.exp(np.array([-z * w + 1j * w * math.sqrt(1 - z * z), -8.0 * w]) / fs)
    a = np.real(np.poly(np.r_[p, np.conj(p)]))
    b = np.array([1.0, 0.5, -0.2, 0.1])
    b = b * a.sum() / b.sum()
    drive = ehss.signals.band_limited_random(band_hz=band, rms=1.0, duration_s=6.0, fs=fs,
                                             seed=3).values
    clean = scipy.signal.lfilter(np.r_[0.0, b], a, drive)
    y_all = clean + 0.01 * np.std(clean) * np.random.default_rng(4).standard_normal(clean.size)
    u, y = drive[3000:4500], y_all[3000:4500]           # a 1.5-s window, not at rest
    settings = CompensationSettings(na=4, nb=3, nc=4, refine=True)
    judging = Judging(fs, settings, AdaptiveCompensator(fs, band))
    start = ehss.ArmaxModel(a=a, b=1.03 * b, c=a, delay=1, dt=1 / fs)
    fit, rows = judging.refine(start, u, y)
    assert 0 < rows < u.size

    def miss(m):   # its error against the loop on the next 1.5 s, the run continued
        k = slice(4500, 6000)
        sim = scipy.signal.lfilter(np.r_[np.zeros(m.delay), m.b], m.a, drive)[k]
        return float(np.sqrt(np.mean((clean[k] - sim) ** 2)) / np.std(clean[k]))

    # the start leaves 3 % (its gain error); the refit the noise's share in the band,
    # about 1 % x sqrt(2 x 19.5 / 1000) = 0.2 %, and what 1.5 s of it leave in the
    # parameters: well under a fifth of the start's
    assert miss(start) > 0.02
    assert miss(fit) < miss(start) / 5.0
    # the compensator's model is a start too; an unstable start is none
    unstable = ehss.ArmaxModel(a=[1.0, -2.1, 1.1], b=[1.0], delay=1, dt=1 / fs)
    assert not unstable.is_stable()
    assert judging.refine(unstable, u, y) == (unstable, 0)
    fit2, rows2 = judging.refine(unstable, u, y, also=start)
    assert rows2 == rows and miss(fit2) < miss(start) / 5.0


@pytest.mark.slow
def test_a_model_off_the_estimate_only_by_its_averaging_raises_no_alarm() -> None:
    # the oil column in steady running (nothing changes) under a 1-40 Hz reference: its
    # models miss the H1 estimate's top point, 39.1 Hz, by 8-14 deg, more than twice
    # the 5-deg bound on some judgements. That point averages the loop over its bin,
    # where the reference ends and the 40 Hz mode turns the phase fast; the estimate
    # of the model's own output through the same segments misses it alike. Three such
    # refusals counted as faults raised an alarm at 7.25 s on these references
    desired = loop_desired(OIL_COLUMN, 30.0, (3, 4), band_hz=(1.0, 40.0))
    rec = _run(SteppingLoop(OIL_COLUMN, desired[:, :int(8.0 * OIL_COLUMN.fs)], preview=128,
                            seed=0))
    assert not [e for e in rec.events if e["kind"] == "alarm"]
    explained = [d for ch in rec.decisions.values() for d in ch if "h1_seen_phase_deg" in d]
    # refused beyond twice the bounds as the estimate is taken, within them as it
    # sees the model (0.0 dB / 0.0 deg beyond its uncertainty measured)
    assert explained
    for d in explained:
        assert not d["accepted"] and d["h1_phase_deg"] > 10.0
        assert d["h1_seen_phase_deg"] <= 10.0 and d["h1_seen_magnitude_db"] <= 2.0


@pytest.mark.slow
def test_models_that_keep_missing_the_band_top_are_judged_as_the_estimate_sees_them(
) -> None:
    # the 8 Hz loop behind a 30 Hz lag under a 0.5-15 Hz reference, +40 % mass at 20 s:
    # the heavier loop falls off faster at the band's top, and its models missed the
    # H1 estimate's top point (15.6 Hz, where the reference ends inside the bin) by
    # 1.1-1.75 dB beyond its uncertainty, 28 refusals in a row; channel 1 stayed at
    # 2.2-3.5x its level before until 28.5 s. Judged against the estimate seen alike
    # once they have missed there three times in a row, its later 2-s stretches are
    # within 1.01x (seeds 1, 2; 1.07-1.24x on seeds 3-6)
    desired = loop_desired(LAGGED, DURATION_S, (1, 2))
    rec = _run(SteppingLoop(LAGGED, desired, preview=128, seed=0, change_s=CHANGE_S,
                            factor=1.4))
    before = rec.tracking_rms(10.0, CHANGE_S)[0]
    for a in np.arange(CHANGE_S + 4.0, DURATION_S, 2.0):
        assert rec.tracking_rms(a, a + 2.0)[0] <= 1.5 * before, a
    assert any(d.get("h1_seen_alike") and d["accepted"] and d["t_s"] > CHANGE_S
               for d in rec.decisions["1"])
    assert not [e for e in rec.events if e["kind"] == "alarm"]


def _rolled_off(spec, duration_s: float, seeds: tuple[int, ...]) -> np.ndarray:
    """White noise through a second-order Butterworth band-pass over 1-40 Hz, at
    ``spec``'s RMS, faded in over 0.2 s: a reference whose spectrum rolls off gently."""
    from scipy import signal

    sos = signal.butter(2, (1.0, 40.0), "bandpass", fs=spec.fs, output="sos")
    out = []
    for seed in seeds:
        x = signal.sosfiltfilt(sos, np.random.default_rng(seed).standard_normal(
            int(duration_s * spec.fs)))
        x *= spec.rms / np.sqrt(np.mean(x**2))
        m = int(0.2 * spec.fs)
        x[:m] *= 0.5 - 0.5 * np.cos(np.pi * np.arange(m) / m)
        out.append(x)
    return np.vstack(out)


@pytest.mark.slow
def test_a_loop_whose_first_models_all_miss_is_compensated_in_the_end() -> None:
    # the specimen under a reference rolled off gently: its 20-dB band reaches over the
    # specimen's resonance (57 Hz), which the reference hardly excites, and the
    # recursive estimate misses the loop there by 2-3 dB / 20-35 deg; refits held to it
    # above the band by their record of it were refused for as long as the run lasted
    # (550-790 um, uncompensated). Refitted without that record once three judgements
    # in a row had failed, each refit going on from the last, a model passed and its
    # inverse was loaded at 2.9-3.75 s (four pairs of references, two noise
    # realisations), with false alarms on three runs of four (seeds 1-4, noise 0, 1).
    # The refit from the data alone (no start, no record) misses the loop far less than
    # the refits from the estimate: loaded at 2.0-2.65 s on those runs, with no alarm
    # (docs/adaptive_compensation.md, "Where the defaults stop")
    desired = _rolled_off(SPECIMEN, 20.0, (1, 2))
    rec = _run(SteppingLoop(SPECIMEN, desired, preview=128, seed=0))
    assert any(d.get("refit_start") == "steiglitz_mcbride" and d["accepted"]
               for ch in rec.decisions.values() for d in ch)
    for name in rec.channels:
        loads = [ld["t_s"] for ld in rec.loads if ld["channel"] == name]
        assert min(loads, default=math.inf) <= 2.75
    assert not [e for e in rec.events if e["kind"] == "alarm"]
    # before any compensator (the drive is the reference) against the last 5 s:
    # measured 21x and 25x (14-29x on the last 5 s of 30-s runs, README)
    early, late = rec.tracking_rms(0.5, 2.0), rec.tracking_rms(15.0, 20.0)
    assert np.all(late <= early / 12.0)


def test_a_loop_behind_a_high_pass_near_the_band_is_compensated() -> None:
    """A 0.5 Hz high-pass in the loop (an AC-coupled sensor, an acceleration generator)
    gives the inverse a mode of about a second whose effect reaches into a band from
    0.5 Hz; the 256-tap FIR, which resolves 4 Hz at 1 kHz, cannot realise it, and its
    designs are refused as realised 13-30 dB off. Run as a section when that happens,
    it is: measured 12.5-24.1x less error than without compensation over [15, 30) s
    on 12 channels (references of seeds 1-6, sensor noise seeds 0 and 1; 13.5x and
    19.5x here), against 6.8-8.6x with the FIR alone."""
    desired = loop_desired(HIGH_PASS, DURATION_S, (1, 2))

    def target() -> SteppingLoop:
        return SteppingLoop(HIGH_PASS, desired, preview=128, seed=0)

    adapted = _run(target())
    plain = target().step(desired.shape[1])
    fs = HIGH_PASS.fs
    err = (plain.desired - plain.feedback)[:, int(15 * fs):]
    uncompensated = np.sqrt(np.mean(err**2, axis=1))
    assert np.all(uncompensated / adapted.tracking_rms(15.0, DURATION_S) >= 10.0)
    sections = [e for e in adapted.events if e["kind"] == "compensator"
                and e.get("settle_samples", 0) > 1000]
    assert sections


def test_a_narrow_low_band_gets_a_window_long_enough_to_judge_it() -> None:
    """The servo under a 0.2-5 Hz reference (a structure's response to an earthquake,
    as hybrid simulation plays it): in the 1.5-s window every H1 estimate had two
    points in the band, every model was refused for it, and the loop ran
    uncompensated. The window that puts 8 points in the band (5 s) judges it: measured
    9.1x and 10.1x less error than without over [10, 20) s of a 20-s run (9.5x and
    9.7x over [30, 60) s of a minute)."""
    settings = CompensationSettings()
    assert settings.h1_window_for((0.2, 5.0)) == pytest.approx(5.0)
    assert settings.h1_window_for((0.5, 20.0)) == 1.5     # the rig's, as before
    assert CompensationSettings(h1_window_s=2.0).h1_window_for((0.2, 5.0)) == 2.0
    duration_s = 20.0
    desired = loop_desired(SERVO, duration_s, (1, 2), band_hz=(0.2, 5.0))

    def target() -> SteppingLoop:
        return SteppingLoop(SERVO, desired, preview=128, seed=0)

    adapted = _run(target())
    # recorded as run: the band found from the reference, 8 points of it (4.9 s)
    band = tuple(adapted.settings["band_hz"])
    assert adapted.settings["h1_window_s"] == pytest.approx(settings.h1_window_for(band))
    assert adapted.settings["h1_window_s"] > 4.0
    plain = target().step(desired.shape[1])
    err = (plain.desired - plain.feedback)[:, int(10 * SERVO.fs):]
    uncompensated = np.sqrt(np.mean(err**2, axis=1))
    assert np.all(uncompensated / adapted.tracking_rms(10.0, duration_s) >= 5.0)


def test_a_sensor_noisier_than_the_fit_allows_is_no_fault() -> None:
    """Sensor noise of 20 % of the reference's RMS on the 25 Hz servo: no model can fit
    the newest 0.25 s of feedback by 90 %, and every judgement was refused as a fault
    of the sensor or the loop: nothing was loaded (0.98x the error without). Against
    the residual the model leaves on the window before them, the fit is the noise's:
    measured 67 loads and 7.1x and 6.9x less error over [10, 20) s (the feedback's own
    noise is most of what is left)."""
    desired = loop_desired(SERVO, 20.0, (1, 2), band_hz=(1.0, 50.0))

    def target() -> SteppingLoop:
        return SteppingLoop(SERVO, desired, preview=128, seed=0, noise=0.2)

    adapted = _run(target())
    plain = target().step(desired.shape[1])
    err = (plain.desired - plain.feedback)[:, int(10 * SERVO.fs):]
    uncompensated = np.sqrt(np.mean(err**2, axis=1))
    assert np.all(uncompensated / adapted.tracking_rms(10.0, 20.0) >= 4.0)
    assert not [e for e in adapted.events if e["kind"] == "alarm"]
