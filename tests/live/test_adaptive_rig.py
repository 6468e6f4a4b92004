"""Adaptive compensation on the simulated rig, run block by block through the target's
filter: two position channels, a 0.5–20 Hz random reference known ahead, +40 % payload
on channel 1 at t = 20 s (and −30 % with other references)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal
from held_inverse import Sending, held
from linear_floor import fixed_linear_floor, stretch_refit_rms, stretch_rms

import ehss
from ehss.compensation.checks import check_drive
from ehss.live.compensate import AdaptiveLoop, CompensationSettings
from ehss.live.rig import RigEvent, RigFault, SteppingRig

FS = 1000.0
BAND = (0.5, 20.0)
RMS_M = 5e-4  # 0.5 mm: the drive's velocity stays within the rig's 0.2 m/s


def _desired(duration_s: float, seeds: tuple[int, int] = (1, 2)) -> np.ndarray:
    return np.vstack([
        ehss.signals.band_limited_random(band_hz=BAND, rms=RMS_M, duration_s=duration_s,
                                         fs=FS, seed=seed, fade_s=0.2).values
        for seed in seeds])


def _rig(desired, *, events=(), faults=(), noise=0):
    return SteppingRig("position", desired, fs=FS, events=events, faults=faults, preview=128,
                       seed=noise)


def _run(desired, *, events=(), faults=(), noise=0, duration_s=None, rig=None):
    """The adaptive loop on the rig (sensor noise seed ``noise``), for ``duration_s`` of
    the reference (default all of it); ``rig``: that rig, already made."""
    rig = _rig(desired, events=events, faults=faults, noise=noise) if rig is None else rig
    settings = CompensationSettings(band_hz=BAND)
    return AdaptiveLoop(rig, settings, loop="position",
                        params=ehss.preset("default")).run(duration_s=duration_s)


#: Stretches after the change judged one by one: 2 s each, from 2 s after it to the end.
_WINDOWS_S = [(t, t + 2.0) for t in np.arange(22.0, 40.0, 2.0)]


@pytest.mark.slow
@pytest.mark.parametrize(("seeds", "factor"),
                         [((1, 2), 1.4), ((3, 4), 1.4), ((1, 2), 0.7), ((3, 4), 0.7)],
                         ids=["+40%", "+40%, other references", "-30%",
                              "-30%, other references"])
def test_adaptation_follows_a_payload_change(seeds, factor):
    check_follows_a_payload_change(seeds, factor, noise=0)


def check_follows_a_payload_change(seeds, factor, *, noise):
    """The figures of a payload change on channel 1 at 20 s, with the rig's sensor noise
    ``noise``: a function of its own so that the bounds can be tried on other
    realisations of the noise as well (docs/adaptive_compensation.md)."""
    desired = _desired(40.0, seeds)
    change = (RigEvent(20.0, "load.mass_kg", factor * ehss.preset("default").load.mass_kg,
                       "1"),)
    sending = Sending(_rig(desired, events=change, noise=noise))
    adapted = _run(desired, rig=sending)
    # the inverse built before the change, held: up to it the adapted run again
    frozen = held(lambda: _rig(desired, events=change, noise=noise), sending.sent, 20.0)
    np.testing.assert_array_equal(frozen.feedback[:, :20_000], adapted.feedback[:, :20_000])
    # the same rig with the new payload from the start, adapted all along
    settled = _run(desired, events=(RigEvent(0.0, change[0].path, change[0].value,
                                             "1"),), noise=noise)
    rig = SteppingRig("position", desired, fs=FS, events=change, preview=128, seed=noise)
    plain = rig.step(desired.shape[1])                            # no compensation
    err = plain.desired - plain.feedback
    uncompensated = np.sqrt(np.mean(err[:, 10_000:20_000] ** 2, axis=1))

    before = adapted.tracking_rms(10.0, 20.0)
    # steady state: the loop lags and attenuates its 0.5-20 Hz reference (~100 % error);
    # the online inverse brings it to a few percent, at least 20 times less
    assert np.all(before <= uncompensated / 20.0)
    # the change is flagged on channel 1 within 1.5 s, as the change detection must (its
    # tracking error rises 9x after +40 %, 4x after -30 %: a few blocks of the
    # trigger's CUSUM; measured 0.3-0.8 s), and on channel 2 never
    changes = [(e["channel"], e["t_s"]) for e in adapted.events
               if e["kind"] == "compensator_change"]
    first = [c for c in changes if c[1] < 30.0]
    assert len(first) == 1 and first[0][0] == "1" and 20.0 < first[0][1] <= 21.5
    assert all(c[0] == "1" for c in changes)
    # once flagged, the change is followed by a correction of the running compensator
    # or a model refitted, both on the data since it (docs/adaptive_compensation.md)
    flagged = [ld for ld in adapted.loads if ld["channel"] == "1" and ld["t_s"] > first[0][1]]
    assert flagged[0]["model"] == "correction" \
        or 0 < flagged[0].get("refit_rows", 0) <= (flagged[0]["t_s"] - 20.0) * FS
    # a change of a healthy loop is followed, not alarmed: models kept out only because
    # the running compensator is better are not faults
    assert not [e for e in adapted.events if e["kind"] == "alarm"]
    # the inverse built before the change, not adapted, stays at least 2x worse in
    # every 2-s stretch from 2 s after the change (measured 4.6-7.5x after +40 %,
    # 4.9-5.4x after -30 %, on the 24 runs below)
    for w in _WINDOWS_S:
        assert frozen.tracking_rms(*w)[0] >= 2.0 * adapted.tracking_rms(*w)[0], w
    # the adaptation is complete: from 2 s after the change to the end, channel 1 within
    # 1.5x of what the rig with the new payload leaves adapted all along, over the same
    # 18 s (measured 0.86-1.55x after +40 %, 1.55x on one noise realisation of twelve,
    # 0.97-1.04x after -30 %)
    assert adapted.tracking_rms(22.0, 40.0)[0] <= 1.5 * settled.tracking_rms(22.0, 40.0)[0]
    # against the level before the change, the aim (1.5x from 2 s after it, in every
    # 2-s stretch) is met after -30 % (measured at most 1.10x); after +40 % it lies
    # within the heavier loop's own level, which the rig with that payload from the
    # start shows as well: 1.10-1.62x the lighter loop's over [10, 20) s, and up to
    # 1.59x in a 2-s stretch later, a stretch scattering by +-40 % about the 10-s level
    # with the content of its reference. Which models a run judges, and so its course
    # after a change, moves with the realisation of the sensor noise and with the
    # rounding of the machine's floating point (its BLAS and SIMD kernels): measured
    # on one machine with noise 0-5 on seeds 1-4, [22, 24) s was 1.05-2.48x and the
    # worst later stretch 1.36-2.07x, the aim met on 3 of those 12 runs (README). The
    # test asserts it where it holds with a margin, and on the heavier loop what the
    # adaptation can reach, above
    if factor < 1.0:
        for w in _WINDOWS_S:
            assert adapted.tracking_rms(*w)[0] <= 1.5 * before[0], w
    # channel 2 does not change: its level after within the scatter of 1-s stretches
    # before (+-30 %)
    assert adapted.tracking_rms(22.0, 40.0)[1] <= 1.3 * before[1]
    # every compensator loaded was taken up and faded in by the target's filter
    assert adapted.loads and all(load["accepted"] for load in adapted.loads)
    # each load's drive within the gain bound (3x) against its reference, and the
    # filter's own largest gain beside it under its own name
    checked = [ld for ld in adapted.loads if "rms_gain" in ld]
    assert checked and all(max(ld["rms_gain"], ld["peak_gain"]) <= 3.0
                           and ld["filter_peak_gain"] > 0.0 for ld in checked)
    for k in range(2):
        check_drive(adapted.drive[k], desired[k], FS, loop="position",
                    params=ehss.preset("default"))


def test_the_aim_after_a_heavier_payload_lies_beyond_any_fixed_linear_inverse():
    """The aim after +40 % payload (the heavier loop within 1.5x the lighter one's level,
    in every 2-s stretch from 2 s after the change) against what the best fixed linear
    inverse, found in hindsight on the whole record, leaves on each payload
    (``linear_floor``): the rig's own nonlinear distortion at that drive."""
    mass = ehss.preset("default").load.mass_kg
    worst, worst_refit = [], []
    for seeds in ((1, 2), (3, 4)):
        desired = _desired(40.0, seeds)
        floor = {}
        for factor in (1.0, 1.4):
            payload = tuple(RigEvent(0.0, "load.mass_kg", factor * mass, c) for c in "12")
            errors = fixed_linear_floor(
                lambda u, payload=payload: _rig(u, events=payload).step(u.shape[1]).feedback,
                desired, FS, BAND)
            last, before_last = (stretch_rms(e, FS, 10.0, 40.0) for e in (errors[-1], errors[-2]))
            # the iteration is at its fixed point: the last run within 2 % of the one
            # before (measured 0.0-0.2 %), and ~100x below the uncompensated error
            assert np.all(np.abs(last / before_last - 1.0) < 0.02)
            assert np.all(last < stretch_rms(errors[0], FS, 10.0, 40.0) / 50.0)
            # what is left is uncorrelated with the reference: the share of its power
            # that a linear filter of the reference explains is the coherence estimate's
            # bias for none, about 1/13 with 13 segments (measured 0.056-0.068); a
            # compensator off its inverse leaves about 0.6 (the adaptive run, seeds 1, 2)
            for k in range(2):
                d, e = desired[k, 10_000:], errors[-1][k, 10_000:]
                _, s_dd = scipy.signal.welch(d, FS, nperseg=4096)
                _, s_de = scipy.signal.csd(d, e, FS, nperseg=4096)
                _, s_ee = scipy.signal.welch(e, FS, nperseg=4096)
                assert np.sum(np.abs(s_de) ** 2 / s_dd) / np.sum(s_ee) < 2.0 / 13.0
            floor[factor] = errors[-1]
        # the heavier loop's own floor lies above the lighter one's (measured 1.23-1.25x
        # over [22, 40) s): larger pressures at the same motion, more of the valve's and
        # the cylinder's nonlinear flow
        heavier = stretch_rms(floor[1.4], FS, 22.0, 40.0)
        assert np.all(heavier > 1.1 * stretch_rms(floor[1.0], FS, 22.0, 40.0))
        before = stretch_rms(floor[1.0], FS, 10.0, 20.0)
        worst.append(np.max([stretch_rms(floor[1.4], FS, *w) / before for w in _WINDOWS_S],
                            axis=0))
        # an inverse changed for each 2-s stretch alone, knowing its error beforehand
        # (to first order: a filter of the reference fitted on the stretch, taken from
        # the error), before the change and after it
        refit_before = np.sqrt(np.mean([stretch_refit_rms(floor[1.0], desired, FS, t, t + 2.0)
                                        ** 2 for t in np.arange(10.0, 20.0, 2.0)], axis=0))
        refit_after = [stretch_refit_rms(floor[1.4], desired, FS, *w) for w in _WINDOWS_S]
        # it takes more than chance from the heavier loop's stretches (129 coefficients
        # on 2000 samples take 6.5 %; measured 20-28 %): the distortion's best linear
        # approximation moves with each stretch's content
        taken = 1.0 - np.mean([(a / stretch_rms(floor[1.4], FS, *w)) ** 2
                               for a, w in zip(refit_after, _WINDOWS_S, strict=True)], axis=0)
        assert np.all(taken > 0.13)
        worst_refit.append(np.max(refit_after, axis=0) / refit_before)
    # and a 2-s stretch of it lies beyond the aim's 1.5x on some reference (measured
    # 1.47, 1.67, 1.42 and 2.38x on the references of seeds 1-4): no fixed linear
    # inverse, even one fitted in hindsight, meets the aim on every reference; a better
    # one lowers the level before more than the heavier loop's distortion after
    assert np.max(worst) > 1.5
    # nor does an inverse fitted in hindsight for each stretch alone, a bound for any
    # linear compensator that adapts, however fast (measured 1.45, 1.61, 1.53, 2.24x)
    assert np.max(worst_refit) > 1.5


@pytest.mark.slow
@pytest.mark.parametrize(("kind", "value"), [("sign", 1.0), ("stuck", 1.0), ("noise", 5.0)])
def test_a_fault_keeps_the_last_good_inverse(kind, value):
    desired = _desired(12.0)
    fault = RigFault(6.0, 9.0, kind, "1", value)
    rec = _run(desired, faults=(fault,))
    ch1 = rec.decisions["1"]
    # a good inverse ran before the fault
    assert any(d["accepted"] and d["t_s"] <= fault.start_s for d in ch1)
    # none from a judgement on data of the fault
    assert not [d for d in ch1 if d["accepted"] and fault.start_s < d["t_s"] <= fault.end_s]
    assert not [ld for ld in rec.loads
                if ld["channel"] == "1" and fault.start_s < ld["t_s"] <= fault.end_s]
    # the refusal is an alarm in the log
    alarms = [e for e in rec.events if e["kind"] == "alarm" and e["channel"] == "1"]
    assert alarms and fault.start_s < alarms[0]["t_s"] <= fault.end_s
    # the drive stays within the gain checks and the rig's limits, and channel 2 runs on
    for k in range(2):
        check_drive(rec.drive[k], desired[k], FS, loop="position",
                    params=ehss.preset("default"))
    assert any(d["accepted"] and fault.start_s < d["t_s"] <= fault.end_s
               for d in rec.decisions["2"])



@pytest.mark.slow
def test_a_running_compensator_whose_drive_breaks_the_limits_is_switched_off():
    # causal mode buys its accuracy in the band with a gain of about 90 above it: 3 % of
    # broadband noise added to channel 1's reference from 10 to 13 s took the drive to
    # 0.8-0.9 m/s against the rig's 0.2 m/s while it lasted, every new compensator
    # refused for it (measured before the switch-off). The reference itself stays
    # within the limits.
    desired = _desired(18.0)
    t = np.arange(desired.shape[1]) / FS
    noisy = (t >= 10.0) & (t < 13.0)
    desired[0, noisy] += 0.03 * RMS_M * np.random.default_rng(5).standard_normal(noisy.sum())
    params = ehss.preset("default")
    check_drive(desired[0], desired[0], FS, max_gain=None, min_gain=None, loop="position",
                params=params)
    rig = SteppingRig("position", desired, fs=FS, preview=0, seed=0)
    settings = CompensationSettings(band_hz=BAND, mode="causal", judge_in="stream")
    rec = AdaptiveLoop(rig, settings, loop="position", params=params).run()
    off = [ld for ld in rec.loads if ld["model"] == "off"]
    assert [ld["channel"] for ld in off] == ["1"], off
    assert 10.0 < off[0]["t_s"] <= 11.0 and "max_velocity_m_s" in off[0]["reason"]
    alarms = [(e["kind"], e["t_s"]) for e in rec.events
              if e["kind"] in ("alarm", "clear") and e["channel"] == "1"]
    assert alarms[0] == ("alarm", off[0]["t_s"])
    # compensated before; from the switch-off's cross-fade to the next load the drive is
    # the reference, within the rig's limits
    loads = [ld for ld in rec.loads if ld["channel"] == "1" and ld["model"] != "off"]
    assert any(ld["t_s"] < 10.0 for ld in loads)
    until = off[0]["apply_index"] + off[0]["crossfade"]
    back = next(ld for ld in loads if ld["t_s"] > off[0]["t_s"])
    np.testing.assert_allclose(rec.drive[0, until:back["apply_index"]],
                               desired[0, until:back["apply_index"]], rtol=0,
                               atol=1e-12 * RMS_M)
    check_drive(rec.drive[0, until:], desired[0, until:], FS, loop="position", params=params)
    # once the noise has left the windows a compensator passes again and the alarm
    # clears (measured 14.25 s), and the tracking is what it was before (measured
    # 46 um against 44 um)
    assert 13.0 < back["t_s"] <= 15.0 and ("clear", back["t_s"]) in alarms
    assert rec.tracking_rms(15.0, 18.0)[0] <= 1.25 * rec.tracking_rms(6.0, 10.0)[0]
    # channel 2 compensated on, within the checks all along
    assert any(ld["channel"] == "2" and ld["t_s"] > 11.0 for ld in rec.loads)
    check_drive(rec.drive[1], desired[1], FS, loop="position", params=params)


def test_causal_compensation_cuts_the_phase_lag():
    # the reference made online (no preview): the compensator is the least-squares causal
    # prediction of the inverse; its phase lag at 10 Hz against the loop's own
    desired = _desired(14.0)[:1]
    rig = SteppingRig("position", desired, fs=FS, preview=0, seed=0)
    rec = AdaptiveLoop(rig, CompensationSettings(band_hz=BAND, mode="causal"),
                       loop="position", params=ehss.preset("default")).run()
    plain = SteppingRig("position", desired, fs=FS, preview=0, seed=0).step(desired.shape[1])
    lag = {}
    for name, y in (("with", rec.feedback[0]), ("without", plain.feedback[0])):
        # the last 8 s, 0.5 Hz bins: 15 averages at a coherence above 0.99 put the phase
        # within a fraction of a degree (Bendat & Piersol 9.92)
        h = ehss.h1_estimate(desired[0, 6000:], y[6000:], fs=FS, nperseg=2000)
        lag[name] = abs(np.degrees(np.angle(h.response[np.argmin(abs(h.freq_hz - 10.0))])))
    assert lag["without"] > 45.0
    assert lag["with"] <= lag["without"] / 10.0
    for k in range(1):
        check_drive(rec.drive[k], desired[k], FS, loop="position",
                    params=ehss.preset("default"))


@pytest.mark.slow
def test_a_worker_process_judges_as_a_worker_thread():
    # the decision is taken up at a fixed sample (the next channel's turn) wherever it is
    # made, so a run judged in a worker process is the one judged on a worker thread,
    # bit for bit; judged on the stream's thread it is taken up at once
    desired = _desired(6.0)
    runs = {}
    for where in ("thread", "process", "stream"):
        rig = SteppingRig("position", desired, fs=FS, preview=128, seed=0)
        settings = CompensationSettings(band_hz=BAND, judge_in=where)
        runs[where] = AdaptiveLoop(rig, settings, loop="position",
                                   params=ehss.preset("default")).run()
    assert runs["thread"].loads
    np.testing.assert_array_equal(runs["process"].drive, runs["thread"].drive)
    assert runs["process"].loads == runs["thread"].loads
    assert runs["process"].decisions == runs["thread"].decisions
    # the stream's thread loads each compensator one turn earlier
    turn = int(round(0.25 / 2 * FS))
    first = {w: next(ld for ld in runs[w].loads if ld["channel"] == "1")
             for w in ("thread", "stream")}
    assert first["thread"]["t_s"] == first["stream"]["t_s"]
    assert first["thread"]["apply_index"] - first["stream"]["apply_index"] >= turn


def test_judging_anywhere_else_is_refused():
    from ehss.errors import ParameterError

    with pytest.raises(ParameterError, match="judge_in"):
        CompensationSettings(band_hz=BAND, judge_in="gpu")


def test_a_correction_needs_a_whole_span_and_time():
    from ehss.errors import ParameterError

    with pytest.raises(ParameterError, match="correction_span"):
        CompensationSettings(band_hz=BAND, correction_span=-1)
    with pytest.raises(ParameterError, match="correct_s"):
        CompensationSettings(band_hz=BAND, correct_s=-1.0)
    assert CompensationSettings(band_hz=BAND).to_dict()["correction_span"] == 2


def test_every_load_compared_only_on_request():
    from ehss.errors import ParameterError

    assert CompensationSettings(band_hz=BAND).to_dict()["load_sigmas"] is None
    assert CompensationSettings(band_hz=BAND, load_sigmas=-2.0).load_sigmas == -2.0
    with pytest.raises(ParameterError, match="load_sigmas"):
        CompensationSettings(band_hz=BAND, load_sigmas=float("nan"))


def test_following_a_change_switches_to_the_short_memory_and_back():
    from ehss.errors import ParameterError
    from ehss.live.compensate import ChannelAdapter

    with pytest.raises(ParameterError, match="follow_memory_s"):
        CompensationSettings(band_hz=BAND, follow_memory_s=0.0)
    with pytest.raises(ParameterError, match="tracker_memory_s"):
        CompensationSettings(band_hz=BAND, tracker_memory_s=-1.0)
    settings = CompensationSettings(band_hz=BAND, memory_s=1.0, tracker_memory_s=0.3,
                                    follow_memory_s=0.3, follow_s=0.5)
    assert settings.to_dict()["follow_memory_s"] == 0.3
    ad = ChannelAdapter("1", FS, BAND, 1.0, settings)
    u = np.random.default_rng(0).standard_normal(2000)
    ad.feed(u[:1000], 0.5 * u[:1000], u[:1000])
    steady = 1.0 - 1.0 / (1.0 * FS)
    short = 1.0 - 1.0 / (0.3 * FS)
    assert ad.estimator.forgetting == steady and ad.tracker.forgetting == short
    bound = ad.estimator.trace_bound
    ad.follow_change()
    # while following: the short memory, its forgetting not held by the bound
    assert ad.estimator.forgetting == short
    assert ad.estimator.trace_bound == settings.follow_trace_bound
    ad.feed(u[1000:1450], 0.5 * u[1000:1450], u[1000:1450])
    assert ad.estimator.forgetting == short
    # follow_s after the trigger: the long memory and the bound of steady running again
    ad.feed(u[1450:1550], 0.5 * u[1450:1550], u[1450:1550])
    assert ad.estimator.forgetting == steady and ad.estimator.trace_bound == bound
    assert ad.tracker.forgetting == short


class _Spoiled:
    """Judges as a channel does, and spoils the first design accepted at or after
    ``at_s``: its FIR part times ``gain``, the inverse of a model whose gain is 1/``gain``
    of the loop's (loaded as any accepted design is)."""

    def __init__(self, judging, at_s: float, gain: float) -> None:
        self.judging, self.at_s, self.gain = judging, at_s, gain
        self.done = False

    def __getattr__(self, name):
        return getattr(self.judging, name)

    def __call__(self, t_s, snap):
        import dataclasses

        from ehss.compensation.adaptive import Decision
        from ehss.live.compensate import Verdict

        verdict = self.judging(t_s, snap)
        d = verdict.decision
        if self.done or t_s < self.at_s or not d.accepted or d.design is None:
            return verdict
        self.done = True
        design = dataclasses.replace(d.design, taps=self.gain * d.design.taps)
        return Verdict(Decision(d.t_s, True, "", design, d.figures), verdict.model,
                       verdict.chosen)


def _run_spoiled(desired, *, events=(), at_s=12.0, gain=0.8):
    rig = SteppingRig("position", desired, fs=FS, events=events, preview=128, seed=0)
    loop = AdaptiveLoop(rig, CompensationSettings(band_hz=BAND), loop="position",
                        params=ehss.preset("default"))
    loop.adapters[0].judging = _Spoiled(loop.adapters[0].judging, at_s, gain)
    return loop.run()


def _loads(rec, channel="1"):
    """The loads of a model's inverse on ``channel`` (rollbacks left out)."""
    return [ld for ld in rec.loads if ld["channel"] == channel and ld["model"] != "rollback"]


@pytest.mark.slow
def test_a_compensator_that_raises_the_error_is_rolled_back():
    # a model 25 % too strong, its inverse 0.8x the loop's: the compensated loop tracks
    # 0.8 of the reference, an error of 20 % of it against a few percent
    at_s = 12.0
    rec = _run_spoiled(_desired(18.0), at_s=at_s)
    spoiled = next(ld for ld in _loads(rec) if ld["t_s"] >= at_s)
    rollbacks = [e for e in rec.events if e["kind"] == "compensator_rollback"]
    assert len(rollbacks) == 1 and rollbacks[0]["channel"] == "1"
    back = rollbacks[0]
    assert back["loaded_index"] == spoiled["apply_index"]
    # sent again as a load is: after the spoiled one has faded in, with its own fade
    assert back["apply_index"] > spoiled["apply_index"] + spoiled["crossfade"]
    assert back["accepted"] and back["ratio"] > 2.0
    assert back in rec.loads
    # not a change of the loop, and not a fault of the compensator
    assert not [e for e in rec.events if e["kind"] in ("compensator_change", "alarm")]
    # the error back at its level: from the rollback's fade-in on, within the scatter
    # of 2-s stretches before the spoiled load (+-30 %)
    end = (back["apply_index"] + back["crossfade"]) / FS
    before = rec.tracking_rms(at_s - 4.0, at_s)
    assert rec.tracking_rms(end, end + 2.0)[0] <= 1.3 * before[0]



@pytest.mark.slow
def test_a_change_soon_after_the_first_compensator_is_followed_not_rolled_back():
    # +40 % payload at 8 s, while a load judged before it fades in (at 8.46 s). The
    # trigger learns the compensated level from the first compensator's takeover on
    # (the uncompensated start, tens of times higher, would widen it), tests from about
    # 8.5 s, finds the rise already there and does not date it to that load: a change of
    # the loop, followed. Learning from the start instead, it dated the rise to the load,
    # and two rollbacks of equally old inverses held channel 1 at 2.7-10x the calm run's
    # level, second by second, until 11 s (measured)
    desired = _desired(14.0, (3, 4))
    change = (RigEvent(8.0, "load.mass_kg", 1.4 * ehss.preset("default").load.mass_kg, "1"),)
    rec = _run(desired, events=change)
    calm = _run(desired)
    assert not [e for e in rec.events if e["kind"] == "compensator_rollback"]
    changes = [(e["channel"], e["t_s"]) for e in rec.events
               if e["kind"] == "compensator_change"]
    assert len(changes) == 1 and changes[0][0] == "1" and 8.0 < changes[0][1] <= 9.5
    # from 2 s after the change, within 2x the unchanged rig (the heavier loop's own
    # level is 1.2-1.4x; measured 1.39-1.47x per second from 10 s)
    for a in (10.0, 12.0):
        assert rec.tracking_rms(a, a + 2.0)[0] <= 2.0 * calm.tracking_rms(a, a + 2.0)[0], a


@pytest.mark.slow
@pytest.mark.parametrize(("seeds", "noise"), [((19, 20), 0), ((7, 8), 1)],
                         ids=["0.21 s before a load", "0.71 s before a load"])
def test_a_change_just_before_a_load_is_told_from_it_and_dated(seeds, noise):
    # -30 % payload at 20 s, before a load judged on the loop of before fades in; the
    # trigger flags the rise at 20.8-21.2 s and dates it into that load's fade-in.
    # The model of before, run on the drive, misses the feedback since then by far more
    # than over the window when the load was sent (14 blocks): a change, followed, and
    # dated by those output errors to 20.0 s. Measured: 0.57x and 0.75x the level
    # before over [22, 24) s. Judged on the blocks the window still held before the
    # load (4, two of them after the change), the first was taken for the load's and
    # rolled back to an inverse as old (1.74x); dated by the trigger, the second's
    # correction waited 0.7 s longer for its rows (1.96x)
    desired = _desired(40.0, seeds)   # the references of the README's table
    change = (RigEvent(20.0, "load.mass_kg", 0.7 * ehss.preset("default").load.mass_kg, "1"),)
    rec = _run(desired, events=change, duration_s=24.0, noise=noise)
    assert not [e for e in rec.events if e["kind"] == "compensator_rollback"]
    changes = [e for e in rec.events if e["kind"] == "compensator_change"]
    assert len(changes) == 1 and changes[0]["channel"] == "1" \
        and 20.0 < changes[0]["t_s"] <= 21.5 and changes[0]["at_load"] is not None
    assert rec.tracking_rms(22.0, 24.0)[0] <= 1.5 * rec.tracking_rms(10.0, 20.0)[0]


@pytest.mark.slow
def test_a_judgement_on_the_loop_before_a_change_is_not_sent():
    # +40 % payload at 20 s; a judgement taken at 20.25 s, on a window still mostly of
    # the loop before, comes back after the change was flagged (20.4 s). Sent, it was
    # an inverse of the loop that was, and the first correction then lacked rows under
    # it: the first refit ran alone at 21.0 s and channel 1 was at 1.75x its level
    # before over [22, 24) s (measured). Not sent, the correction races the refit
    # there and wins: about 1.3x
    desired = _desired(40.0, (7, 8))   # the references of the README's table
    change = (RigEvent(20.0, "load.mass_kg", 1.4 * ehss.preset("default").load.mass_kg, "1"),)
    rec = _run(desired, events=change, duration_s=24.0)
    flagged = next(e["t_s"] for e in rec.events if e["kind"] == "compensator_change")
    stale = [e for e in rec.events if e["kind"] == "compensator_refused"
             and "judged on the loop before the change" in e["reason"]]
    assert stale and all(e["t_s"] < flagged for e in stale)
    assert rec.tracking_rms(22.0, 24.0)[0] <= 1.5 * rec.tracking_rms(10.0, 20.0)[0]


def _earthquake_like(duration_s: float, seed: int) -> np.ndarray:
    """0.5–15 Hz random motion under an envelope: a rise over 3 s, 12 s of strong
    motion at 0.5 mm RMS, then a coda that dies away (time constant 6 s), as the
    records a shaking table plays do."""
    t = np.arange(int(duration_s * FS)) / FS
    x = ehss.signals.band_limited_random(band_hz=(0.5, 15.0), rms=1.0, duration_s=duration_s,
                                         fs=FS, seed=seed, fade_s=0.2).values
    x = x * np.where(t < 3.0, (t / 3.0) ** 2,
                     np.where(t < 15.0, 1.0, np.exp(-(t - 15.0) / 6.0)))
    return RMS_M * x / np.sqrt(np.mean(x[int(3 * FS):int(15 * FS)] ** 2))


@pytest.mark.slow
def test_a_record_that_dies_away_raises_no_alarm_but_a_fault_still_does():
    # in the coda the feedback is soon mostly the sensor's noise, which no model fits by
    # 90 %: judged a fault, the fits below it alarmed on both channels in the last 5 s
    # (34.9-36.75 s, measured); within the residual the channel's loads left, they are a
    # quiet feedback. Channel 1's sensor sticks in the coda (30-33 s, the reference at
    # 8 % of its strong level): its residual is the feedback's own size, several times
    # the usual one, and it alarms (at 31.5 s, measured); channel 2 does not
    desired = np.vstack([_earthquake_like(40.0, seed) for seed in (1, 2)])
    rig = SteppingRig("position", desired, fs=FS, faults=(RigFault(30.0, 33.0, "stuck", "1"),),
                      preview=128, seed=0)
    rec = AdaptiveLoop(rig, CompensationSettings(), loop="position",
                       params=ehss.preset("default")).run()
    alarms = [(e["channel"], e["t_s"]) for e in rec.events if e["kind"] == "alarm"]
    assert [c for c, _ in alarms] == ["1"] and 30.0 < alarms[0][1] <= 33.0
    assert not [d for d in rec.decisions["1"] if d["accepted"] and 30.0 < d["t_s"] <= 33.0]
    # and compensated all along: the strong motion tracked within 2 % (measured
    # 6.2-6.3 um of 500)
    assert np.all(rec.tracking_rms(3.0, 15.0) < 0.02 * RMS_M)


@pytest.mark.slow
def test_a_pause_in_the_reference_keeps_the_compensator_and_raises_no_alarm():
    # the reference stops from 20 to 30 s (faded out and in over 0.2 s), as between two
    # tests while the stream goes on: nothing in the band to judge a model on, and the
    # estimator drifts where nothing excites it. Judged as before, the H1 and polarity
    # guards failed as faults: alarms 1.25 and 1.4 s after the stop (measured); with
    # quiet windows skipped only as a whole, on both channels as the reference came
    # back (30.4-30.5 s); judgements on windows a third of which is quiet are skipped
    # instead
    desired = _desired(33.0)
    t = np.arange(desired.shape[1]) / FS
    gain = np.clip(np.maximum(20.0 - t, t - 30.0) / 0.2, 0.0, 1.0)
    desired = desired * gain
    rec = _run(desired)
    assert [e for e in rec.events if e["kind"] == "alarm"] == []
    for name in rec.channels:
        paused = [d for d in rec.decisions[name] if 20.5 < d["t_s"] < 30.0]
        assert paused and all(not d["accepted"] and "quiet" in d["reason"] for d in paused)
    # the compensator of before the pause runs on after it (measured 1.18x and 1.31x the
    # level before over the first 1.5 s, with no load in between)
    before, after = rec.tracking_rms(10.0, 20.0), rec.tracking_rms(30.2, 31.7)
    assert np.all(after <= 1.5 * before)


@pytest.mark.slow
def test_a_sine_dwell_after_a_random_reference_raises_no_alarm():
    # random for 20 s, then a sine dwell (5 Hz on channel 1, 12 Hz on channel 2) from
    # 20.5 s: the compensator of the random part tracks the sines (measured 3.5-4.1 um,
    # against 299 and 572 um without), but the models of a sine, compared with the H1
    # estimate's points beside it, were refused as faults and both channels alarmed at
    # 22.15-22.25 s (measured)
    desired = _desired(30.0)
    t = np.arange(desired.shape[1]) / FS
    w = np.clip((t - 20.0) / 0.5, 0.0, 1.0)
    sines = RMS_M * np.sqrt(2.0) * np.sin(2 * np.pi * np.array([[5.0], [12.0]]) * t)
    desired = desired * (1.0 - w) + sines * w
    rec = _run(desired)
    assert [e for e in rec.events if e["kind"] == "alarm"] == []
    assert np.all(rec.tracking_rms(22.0, 30.0) <= 2.0 * rec.tracking_rms(10.0, 20.0))
    for name in rec.channels:
        assert any("single sine" in d["reason"] for d in rec.decisions[name] if d["t_s"] > 22)


def test_models_that_keep_missing_the_bands_lowest_point_are_judged_above_it():
    # three refusals in a row furthest at the band's lowest point (alarm_after) let the
    # next models be validated above it; a model accepted over the band above keeps
    # that, one accepted over the whole band ends it, and a refusal for another reason
    # or elsewhere in the band counts nothing
    from ehss.compensation.adaptive import Decision
    from ehss.live.compensate.adapter import _at_edge

    def edge(at):
        return Decision(1.0, False, "misses", figures={"h1_worst_hz": at,
                                                      "h1_lowest_hz": 1.95})

    above = Decision(1.0, True, "", figures={"validated_from_hz": 2.6})
    whole = Decision(1.0, True, "", figures={})
    other = Decision(1.0, False, "unstable")
    count = 0
    for d, expected in [(edge(1.95), 1), (edge(19.5), 1), (other, 1), (edge(1.95), 2),
                        (edge(1.95), 3), (edge(1.95), 3), (above, 3), (edge(1.95), 3),
                        (whole, 0), (edge(1.95), 1)]:
        count = _at_edge(count, d, 3)
        assert count == expected, d
    # the band's highest point: the same count, of refusals furthest there
    top = [Decision(1.0, False, "misses", figures={"h1_worst_hz": 99.6,
                                                   "h1_highest_hz": 99.6}),
           Decision(1.0, True, "", figures={"validated_to_hz": 98.6})]
    count = 0
    for d, expected in [(edge(1.95), 0), (top[0], 1), (top[0], 2), (top[0], 3), (top[1], 3),
                        (above, 0)]:
        count = _at_edge(count, d, 3, top=True)
        assert count == expected, d
    settings = CompensationSettings(band_hz=BAND)
    assert settings.alarm_after == 3


def test_drives_that_keep_failing_the_checks_narrow_the_band():
    # three validated models in a row whose drives failed the gain checks or the rig's
    # limits (alarm_after) let the next be narrowed to where its drive passes; a load
    # narrowed keeps that, one over the whole band ends it, and a refusal for another
    # reason counts nothing
    from ehss.compensation.adaptive import Decision
    from ehss.live.compensate.adapter import _over

    over = Decision(1.0, False, "the drive's RMS is 4.9x", figures={"drive_refused": True})
    narrowed = Decision(1.0, True, "", figures={"narrowed_to_hz": 72.3})
    whole = Decision(1.0, True, "", figures={})
    other = Decision(1.0, False, "misses", figures={"h1_worst_hz": 99.6})
    count = 0
    for d, expected in [(over, 1), (other, 1), (over, 2), (over, 3), (over, 3),
                        (narrowed, 3), (other, 3), (whole, 0), (over, 1)]:
        count = _over(count, d, 3)
        assert count == expected, d


@pytest.mark.slow
def test_a_change_soon_after_a_trigger_and_a_new_test_level_is_flagged():
    # references of seeds 3, 4 at half level, doubled at 20 s (0.2-s ramp), +40 %
    # payload on channel 1 at 23 s. A load's rise at 17.9 s is taken for a change of
    # the loop; the trigger, blind for learn_s + lag_s after it before, left the payload
    # change unflagged and channel 1 at 57-83 um per 0.5 s until 25 s. Tested on from the
    # first compensator that follows the trigger, it flags the payload (measured at
    # 23.7 s). On these 28 s of reference it also flags the doubled level (at 20.7 s),
    # where the level test on 2 blocks cannot tell it (on the 40-s references it takes
    # it for a new test level, and flags the payload at 23.3 s: README)
    desired = _desired(28.0, (3, 4))
    t = np.arange(desired.shape[1]) / FS
    desired *= 0.5 + 0.25 * (1.0 - np.cos(np.pi * np.clip((t - 20.0) / 0.2, 0.0, 1.0)))
    change = (RigEvent(23.0, "load.mass_kg", 1.4 * ehss.preset("default").load.mass_kg,
                       "1"),)
    rec = _run(desired, events=change)
    kinds = [(e["kind"], e["t_s"]) for e in rec.events if e.get("channel") == "1"
             and e["kind"] in ("compensator_change", "compensator_level")]
    assert kinds[0][0] == "compensator_change" and 17.0 < kinds[0][1] < 20.0, kinds
    assert any(kind == "compensator_change" and 23.0 < t_s <= 24.5 for kind, t_s in kinds), kinds
    # followed: from 2 s after the change channel 1 within 2x channel 2 (the heavier
    # loop's own level at the doubled test level is 1.5-2x the lighter's; measured
    # 1.55x over [25, 28) s)
    after = rec.tracking_rms(25.0, 28.0)
    assert after[0] <= 2.0 * after[1], after
