"""How a channel's model is judged, away from the stream: the copy of the channel a
judgement takes (:class:`Snapshot`), the judgement (:class:`Judging`, which compares the
model with an H1 estimate as that estimate sees it: :func:`seen_alike`) and its outcome
(:class:`Verdict`).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, cast

import numpy as np

import ehss
from ehss._settle import SETTLE_TIME_CONSTANTS, decay_samples
from ehss.compensation.adaptive import (
    H1_DISAGREES,
    AdaptiveCompensator,
    Decision,
    free_run_fit,
)
from ehss.compensation.compensator_design import CompensatorDesign
from ehss.compensation.correction import compare_compensators, fit_correction
from ehss.errors import EhssError
from ehss.frequency import FrequencyResponse
from ehss.identification import oe_pem
from ehss.live.compensate.settings import CompensationSettings
from ehss.validation import frf_error

#: Independent samples of the band per parameter that a model's refit to its output
#: errors needs (:meth:`Judging.refine`), a record of T s in a band of B Hz holding
#: about 2 B T of them: two, half as many as a correction's taps ask
#: (:func:`~ehss.compensation.correction.fit_correction`), since a refit starts next to
#: its answer (the recursive estimate, the running model) and its prior record holds
#: the loop above the band, which the rows do not. Four made it come after the correction on the
#: simulated rig (0.81 s against 1.23 s of data), which left −30 % payload on one pair
#: of references at 2.6× over the first 2 s (docs/adaptive_compensation.md).
REFINE_SAMPLES = 2
#: A reference this far below its usual RMS (20 dB) is quiet (:meth:`Judging._quiet`).
QUIET_REFERENCE = 0.1
#: Evaluations of each of a refit's Levenberg–Marquardt runs (from a nearby start it
#: converges in 4–8; 30 changed no figure of the README's rig tables)
REFINE_EVALUATIONS = 15
#: A refit from the data alone (no start, no record above the band) replaces the best
#: refit from the starts only if it leaves at most this share of that one's output error
#: (:meth:`Judging.refine`). Fitted on the same rows, a model with p more free
#: parameters gains about p/ν of the squared error by chance (ν independent samples of
#: the band, at least :data:`REFINE_SAMPLES` × p): a few percent, where a third of
#: the error is a ninth of its square. Such a gain says the starts' refits are held in
#: a local minimum, not that the data were overfitted: on the simulated rig no refit
#: from the data came near it, and the runs are the same to the bit with it or without.
DATA_REFIT_SHARE = 1.0 / 3.0
#: Its start: the Steiglitz–McBride iterations (``starts`` of
#: :func:`ehss.identification.oe_pem`). Their refit won over the ARX fit's in every
#: judgement on the oil-column loop, and the ARX fit's alone changed nothing there: it
#: would double the refit's work for nothing.
DATA_REFIT_STARTS = ("steiglitz_mcbride",)
#: Seed of the noise that carries the prior (:meth:`Judging._prior`)
PRIOR_SEED = 0
#: Length of that noise in start-ups of the prior (or in its parameters, if more)
PRIOR_LENGTH = 4


@dataclass(frozen=True)
class Snapshot:
    """A channel's windows (drive, feedback, desired reference, oldest first) and its
    averaged θ̂ (estimator's, then tracker's; shape (1 or 2, n_params)) at one time;
    while a change is corrected, the compensator corrected and the spans of the windows
    since the change, each with the correction that ran then (``spans`` of
    :func:`~ehss.compensation.correction.fit_correction`; empty: judge the model); the
    compensator that runs, and the spans of the windows that each compensator ran
    alone since the latest change (``spans`` of
    :func:`~ehss.compensation.correction.compare_compensators`); the first sample of the
    windows since the latest change of the loop (0: it came before them); whether the
    refits go without their record above the band, and then the latest model refitted
    and not loaded, where the next refit goes on from (:meth:`Judging.refine`); the
    channel's usual residual on fresh data and the reference's usual RMS over the
    window (the medians over its recent loads; None before
    :data:`~ehss.live.compensate.adapter.RESIDUAL_LOADS` of them:
    :meth:`AdaptiveCompensator._judge_fit`, :meth:`Judging._quiet`); how far its models
    usually miss the H1 estimate (:data:`~ehss.live.compensate.adapter.USUAL_DISAGREEMENT`);
    whether they keep missing it at the band's lowest point (``low_edge``) or at its
    highest (``top_edge``), and whether
    their drives keep failing the gain checks or the rig's limits (``narrow_top``; both
    :meth:`AdaptiveCompensator.assess`); whether they keep missing it at its highest
    point, drives failing or not, so that in steady running too the estimate sees the
    model as it sees the loop (``top_biased``: :meth:`Judging._h1`)."""

    drive: np.ndarray
    feedback: np.ndarray
    desired: np.ndarray
    thetas: np.ndarray
    running: CompensatorDesign | None = None
    spans: tuple = ()
    current: CompensatorDesign | None = None
    ran: tuple = ()
    fresh: int = 0
    running_model: ehss.ArmaxModel | None = None
    unanchored: bool = False
    refitted: ehss.ArmaxModel | None = None
    residual_floor: float | None = None
    reference_level: float | None = None
    disagreement: tuple[float, float] | None = None
    low_edge: bool = False
    top_edge: bool = False
    narrow_top: bool = False
    top_biased: bool = False


@dataclass(frozen=True)
class Verdict:
    """A judgement: the decision, the model judged (None if there was none) and whose
    model it is (``"estimator"`` or ``"tracker"``; ``"correction"`` for a correction of
    the running compensator, with no model)."""

    decision: Decision
    model: ehss.ArmaxModel | None
    chosen: str


class Judging:
    """How a channel's snapshot is judged; changes nothing, so that it can run on a
    worker thread or in a worker process (a copy) while the stream is fed.

    Parameters
    ----------
    fs : float
    settings : CompensationSettings
    compensator : AdaptiveCompensator
        Whose :meth:`~AdaptiveCompensator.assess` decides (its state is not touched).
    """

    def __init__(self, fs: float, settings: CompensationSettings,
                 compensator: AdaptiveCompensator) -> None:
        self.fs = float(fs)
        self.settings = settings
        self.compensator = compensator
        lo, hi = compensator.band_hz
        n_taps = 2 * settings.correction_span + 1
        # a correction's fit: four times as many independent samples as taps, a record
        # of T s in a band of B Hz holding about 2 B T of them; then the guard's fresh
        # stretch to check it on, and a period of the upper edge where the zero-phase
        # filter's end is not settled
        self.n_fit = int(math.ceil(4 * n_taps * self.fs / (2.0 * (hi - lo))))
        self._n_check = max(1, int(round(settings.guard.fit_s * self.fs)))
        self.correction_rows = self.n_fit + self._n_check + int(math.ceil(self.fs / hi))
        # a load's check: stretches that hold about four independent samples of the band
        self._n_chunk = int(math.ceil(4 * self.fs / (2.0 * (hi - lo))))
        #: rows since a change that a refit of the model needs (:meth:`refine`)
        self.refine_rows = self._refine_rows(settings.na + settings.nb + 1)

    def models(self, thetas: np.ndarray) -> list[ehss.ArmaxModel]:
        """The models of averaged θ̂ (rows: estimator, tracker)."""
        s = self.settings
        return [ehss.ArmaxModel(a=np.r_[1.0, th[:s.na]], b=th[s.na:s.na + s.nb + 1],
                                c=np.r_[1.0, th[s.na + s.nb + 1:]], delay=s.delay,
                                dt=1.0 / self.fs) for th in thetas]

    def model(self, thetas: np.ndarray, u: np.ndarray | None, y: np.ndarray | None
              ) -> tuple[ehss.ArmaxModel, str]:
        """Of :meth:`models`, the one that fits the latest ``guard.fit_s`` of ``y`` better
        in free run on ``u``, and whose it is."""
        models = self.models(thetas)
        if u is None or y is None or len(models) == 1:
            return models[0], "estimator"
        n_fit = max(1, min(int(round(self.settings.guard.fit_s * self.fs)), u.size // 2))
        best = int(np.argmax([free_run_fit(m, u, y, n_fit) for m in models]))
        return models[best], ("estimator", "tracker")[best]

    def refine(self, model: ehss.ArmaxModel, u: np.ndarray, y: np.ndarray, fresh: int = 0,
               also: ehss.ArmaxModel | None = None, *, prior: bool = True,
               then: ehss.ArmaxModel | None = None) -> tuple[ehss.ArmaxModel, int]:
        """``model``'s dynamics refitted to the windows' output errors, and the rows
        it was refitted on (0: not refitted).

        The tracking error a compensator C' = M⁻¹ will leave is (M − G) M⁻¹ r, and
        M⁻¹ r is the drive it gives: it is the output error y − M u of M on that
        drive, which the recursive estimator does not minimise (its one-step
        prediction errors weight the band by its noise model; the bias of a sixth-order
        model of a higher-order, nonlinear loop falls where that weight is low). So
        the model, as a start, is refitted by output-error minimisation
        (:func:`ehss.identification.oe_pem`) on the rows since the loop's latest
        change (``fresh``, the rows before only run it from rest) or since the model's
        own start-up from rest has died out (:func:`_start_up`), whichever is later,
        if they hold :data:`REFINE_SAMPLES` independent samples of the band per
        parameter, with a record of the start above the band (:meth:`_prior`; not with
        ``prior`` False, below). It starts from ``model`` and from ``also`` (the model
        of the compensator that runs): of the starts and their refits, the one that
        fits those rows best in free run is returned; ``model`` if none does better or
        the fit fails. An unstable start is none (its start-up never dies out). The
        refit's poles stay within the radius whose modes die out (e⁻⁷) within half the
        rows: slower ones are not determined by them.

        The record holds a refit to its start above the band, and near the band's top
        (whose response the start's structure ties to the one above it). A channel on
        which no compensator runs yet and whose latest judgements were all refused as
        faults (``alarm_after`` of them: :attr:`Snapshot.unanchored`) has no start that
        an H1 estimate has confirmed, and where the recursive estimate misses the loop
        the record holds every refit to that miss: the 4 kHz specimen under a
        reference rolled off by a second-order filter, whose 20-dB band reaches over
        its resonance, had models 2–3 dB / 20–35° off there and was never compensated
        (550–790 µm). There the refits go without it until a compensator is loaded,
        and start from ``then`` as well (the latest refit that was not loaded): their
        few evaluations each go on where the last stopped, instead of starting again
        from the same estimate (first loads at 2.9–3.75 s on four pairs of references,
        against 3.5–9.9 s).

        A refit from the data alone (``oe_pem``'s own Steiglitz–McBride start, without
        the record) is tried last, and taken only if it leaves at most
        :data:`DATA_REFIT_SHARE` of the best's output error. The record holds the
        refits to their start above the band and near its top, and where the loop
        has a lightly damped mode there, to the start's miss of it: on a 15 Hz loop with
        a 40 Hz, ζ 0.15 oil-column mode at 2 kHz over 1–40 Hz, every refit from the
        recursive estimate stopped at a fit of 90–92 % (0.5–0.9 dB / 4–6° off across
        the band), the one from the data alone at 99 % (within 0.02 dB), and the
        compensated error fell from 1/13 of the uncompensated to 1/120."""
        s = self.settings
        starts = [m for m in (model, also, then) if m is not None and m.is_stable()
                  and m.a.size == s.na + 1 and m.b.size == s.nb + 1]
        if s.refine is False or not starts:
            return model, 0
        settle = min(_start_up(m) for m in starts)
        # from rest, or from the state the change left the loop in: the rows that hold
        # the response to the loop as it was die out as a start-up does
        start = int(fresh) + settle if fresh else settle
        n = u.size - start
        if n < self.refine_rows:
            return model, 0
        radius = math.exp(-SETTLE_TIME_CONSTANTS / (0.5 * n))
        best, score = model, free_run_fit(model, u, y, n)
        for m in starts:
            try:
                fit = oe_pem(u, y, nf=s.na, nb=s.nb, delay=s.delay, dt=1.0 / self.fs,
                             theta0=np.r_[m.a[1:], m.b], first=start,
                             records=[self._prior(m, n, u[start:])] if prior else [],
                             max_nfev=REFINE_EVALUATIONS, radius=radius)
            except EhssError:
                continue
            fit_score = free_run_fit(fit, u, y, n)
            if fit_score > score:
                best, score = fit, fit_score
        try:
            data = oe_pem(u, y, nf=s.na, nb=s.nb, delay=s.delay, dt=1.0 / self.fs,
                          first=start, max_nfev=REFINE_EVALUATIONS, radius=radius,
                          starts=DATA_REFIT_STARTS)
        except EhssError:
            data = None
        # output errors as shares of the feedback's spread: 1 − fit/100
        if data is not None and (100.0 - free_run_fit(data, u, y, n)
                                 <= DATA_REFIT_SHARE * (100.0 - score)):
            best = data
        return best, 0 if best is model else n

    def _prior(self, prior: ehss.ArmaxModel, n: int, drive: np.ndarray) -> tuple:
        """A record of ``prior`` for a refit of ``n`` rows of ``drive``
        (``records`` of :func:`ehss.identification.oe_pem`): its response to white
        noise with nothing below the band's upper edge. The drive is band-limited, so
        the rows say nothing of the loop above the band, where a refit alone puts sharp
        features that the target's filter cannot realise: there the prior rules,
        weighted to say as much as the rows do (weight² × its power = the rows' power
        of the drive), and it says nothing in the band. The noise is
        :data:`PRIOR_LENGTH` times as long as the prior's own start-up or its
        parameters, and no longer than the rows."""
        hi = self.compensator.band_hz[1]
        length = min(n, PRIOR_LENGTH * max(_start_up(prior), prior.a.size + prior.b.size))
        spectrum = np.fft.rfft(np.random.default_rng(PRIOR_SEED).standard_normal(length))
        spectrum[np.fft.rfftfreq(length, 1.0 / self.fs) <= hi] = 0.0
        noise = np.fft.irfft(spectrum, length)
        noise *= float(np.sqrt(np.mean(drive ** 2))) / max(float(np.std(noise)), 1e-300)
        return noise, prior.simulate(noise), math.sqrt(n / length)

    def _h1(self, model: ehss.ArmaxModel, u: np.ndarray, y: np.ndarray, fresh: int,
            top_biased: bool = False) -> FrequencyResponse:
        """The H1 estimate of the loop as it is now that ``model`` is judged against:
        over the rows since its latest change (``fresh`` on), in segments of a third of
        them (a power of two: 4 averages with half overlap).

        Since a change, the segments are short (256 samples at 1 kHz 0.75 s after it)
        and their points are biased where the loop lags or the drive's spectrum ends
        within a bin: each segment of the feedback is read as late as it lags the drive
        (``delay="auto"``), and each point is compared with the model as the estimate
        sees it (:func:`seen_alike`). On a 12 Hz loop behind two samples of delay, the
        model refitted 0.75 s after +40 % mass was refused 16.4° off at the band's top
        (0.3° as the estimate sees the model), and the error took 2.5–3 s to come
        back (1.26–1.43× its level before over [2, 4) s after the change now).

        In steady running the estimate is taken as it is (a refusal there keeps a
        compensator that tracks well; on the simulated rig, taken out there too, the
        bias changed which models were loaded and left the aim after ±40 % payload as
        often met, on 24 runs), unless the channel's models keep missing it at the
        band's highest point (``top_biased``): there the loop's response is averaged
        over a bin where the drive ends, and the bias grows with the response's slope.
        An 8 Hz, ζ 0.6 loop behind a 30 Hz lag at 1 kHz under a 0.5–15 Hz reference,
        after +40 % mass, had 28 models in a row refused at 15.6 Hz by 1.1–1.75 dB
        and stayed at 2.2–3.5× its level before for 8 s; judged seen alike once three
        had missed there, its 2-s stretches from 4 s after the change were within 1.01×
        (seeds 1, 2)."""
        uh, yh = u[fresh:], y[fresh:]
        nper = min(int(2 ** round(math.log2(max(16, uh.size / 3)))), uh.size)
        if not fresh:
            h1 = ehss.h1_estimate(uh, yh, fs=self.fs, nperseg=nper)
            return seen_alike(model, h1, u, 0) if top_biased else h1
        h1 = ehss.h1_estimate(uh, yh, fs=self.fs, nperseg=nper, delay="auto")
        return seen_alike(model, h1, u, fresh)

    def rows_to_refit(self, running: ehss.ArmaxModel | None) -> int:
        """Rows since a change that a refit needs: :attr:`refine_rows` after the
        start-up of the ``running`` model (:meth:`refine`)."""
        return self.refine_rows + (0 if running is None or not running.is_stable()
                                   else _start_up(running))

    def _refine_rows(self, n_params: int) -> int:
        lo, hi = self.compensator.band_hz
        return int(math.ceil(REFINE_SAMPLES * n_params * self.fs / (2.0 * (hi - lo))))

    def correct(self, t_s: float, snap: Snapshot) -> Verdict:
        """The correction of the running compensator fitted to the fresh samples of
        ``snap``, judged (:meth:`AdaptiveCompensator.assess_correction`)."""
        comp = self.compensator
        try:
            corr = fit_correction(snap.desired, snap.feedback, fs_hz=self.fs,
                                  band_hz=comp.band_hz, spans=snap.spans,
                                  n_check=self._n_check,
                                  half_span=self.settings.correction_span,
                                  base=snap.running)
        except EhssError as exc:
            return Verdict(Decision(t_s, False, f"no correction: {exc}"), None, "correction")
        return Verdict(comp.assess_correction(t_s, corr, snap.running, snap.desired), None,
                       "correction")

    def __call__(self, t_s: float, snap: Snapshot) -> Verdict:
        quiet = self._quiet(snap)
        if quiet:
            return Verdict(Decision(t_s, False, quiet, fault=False), None, "")
        u = snap.drive
        fresh = snap.fresh if self.settings.refine is not False else 0
        if snap.spans:
            corrected = self.correct(t_s, snap)
            if fresh and u.size - fresh >= self.rows_to_refit(snap.running_model):
                return self._better(corrected, self._model_verdict(t_s, snap, fresh), snap)
            return corrected
        return self._model_verdict(t_s, snap, fresh)

    def _better(self, corrected: Verdict, refitted: Verdict, snap: Snapshot) -> Verdict:
        """Of a correction and a refitted model, judged on the same rows since a change,
        the one that leaves less tracking error where the correction was checked (the
        newest rows, which it was not fitted to; the model was), if both pass and those
        rows ran the compensator both would replace; else the correction if it passes,
        the model if only it does.

        Which one is better depends on the loop and the change: on the simulated rig,
        1 s after +40 % payload, the correction left 13–19 % of the running one's error
        and the refit 17–25 %; on a 12 Hz loop behind 2 ms of delay the correction, a
        short FIR, left 33–46 % and the refit 9–19 %. The refit therefore waits for the
        first correction while the rows since the change are too few for one
        (:meth:`ChannelAdapter.ready`): judged alone 0.25 s earlier, the rig's first
        refits were loaded and left 2.3× its level before where the correction would
        have left 1.4×."""
        c, m = corrected.decision, refitted.decision
        if not m.accepted or m.design is None or snap.running is None:
            return corrected
        last_a, last_b, then = snap.spans[-1]
        if not c.accepted or then is not None:
            return refitted if not c.accepted else corrected
        cmp = compare_compensators(m.design, snap.running, snap.desired, snap.feedback,
                                   ((max(last_a, last_b - self._n_check - m.design.preview),
                                     last_b, None),), chunk=self._n_chunk)
        c.figures["refit_leaves"] = m.figures["refit_leaves"] = cmp.ratio
        m.figures["correction_leaves"] = float(c.figures["check_ratio"])
        if math.isfinite(cmp.ratio) and cmp.ratio < float(c.figures["check_ratio"]):
            return refitted
        return corrected

    def _model_verdict(self, t_s: float, snap: Snapshot, fresh: int) -> Verdict:
        u, y = snap.drive, snap.feedback
        if fresh and u.size - fresh < self.rows_to_refit(snap.running_model):
            return Verdict(Decision(t_s, False, f"{u.size - fresh} samples since the change "
                                    "of the loop: too few to refit its model yet",
                                    fault=False), None, "")
        try:
            model, chosen = self.model(snap.thetas, u, y)
            model, rows = self.refine(model, u, y, fresh, also=snap.running_model,
                                      prior=not snap.unanchored, then=snap.refitted)
            h1 = self._h1(model, u, y, fresh, snap.top_biased)
        except EhssError as exc:
            return Verdict(Decision(t_s, False, f"no model or H1 estimate: {exc}"), None, "")
        decision = self.compensator.assess(t_s, model, h1, snap.desired, window=(u, y),
                                           running=snap.current,
                                           residual_floor=snap.residual_floor,
                                           usual_disagreement=snap.disagreement,
                                           low_edge=snap.low_edge,
                                           top_edge=snap.top_edge,
                                           narrow_top=snap.narrow_top)
        if not fresh and snap.top_biased:
            decision.figures["h1_seen_alike"] = True
        elif not fresh:
            decision = self._bias_explained(decision, model, h1, u, snap)
        if rows:
            decision.figures["refit_rows"] = rows
            decision.figures["refit_start"] = str(model.meta.get("start", "given"))
        if fresh:
            decision.figures["fresh_rows"] = int(u.size - fresh)
        decision.figures["reference_rms"] = float(np.std(snap.desired))
        if decision.accepted and decision.design is not None and snap.current is not None \
                and snap.ran:
            decision = self._against_running(decision, snap)
        return Verdict(decision, model, chosen)

    def _bias_explained(self, decision: Decision, model: ehss.ArmaxModel,
                        h1: FrequencyResponse, u: np.ndarray, snap: Snapshot) -> Decision:
        """``decision``, no fault if it refused the model for missing the H1 estimate
        grossly and the model, compared with the estimate as the estimate sees it
        (:func:`seen_alike`), misses it only narrowly: the estimate's averaging over its
        bins, not the model, is then what misses. The refusal stands (in steady running
        the estimate is taken as it is, :meth:`_h1`); only the alarm it would count
        towards goes.

        A point averages the loop's response over the window's main lobe weighted by
        the drive's spectrum, so where that spectrum ends inside a bin, at the band's
        top, the point is the loop's response a little below it. Under a lightly damped
        mode near the top, whose phase turns fast there, that is degrees off: on a 15 Hz
        loop with a 40 Hz, ζ 0.15 oil-column mode under a 1–40 Hz reference, the
        models of a loop in steady running missed the point at 39.1 Hz by 8–14° (the
        bound of a near miss: 10°), and three such refusals raised an alarm 7 s into a
        run. A feedback flipped, a stuck sensor or a drowned one still alarm
        (``tests/live/test_adaptive_rig.py``)."""
        if decision.accepted or not decision.fault \
                or not decision.reason.startswith(H1_DISAGREES):
            return decision
        comp = self.compensator
        acc = comp.guard.acceptance
        seen = seen_alike(model, h1, u, 0)
        if seen is h1:
            return decision
        err = frf_error(cast(Any, model), seen, band_hz=comp.band_hz,
                        min_coherence=acc.min_coherence)
        mag_db, ph_deg = err.beyond_uncertainty(acc.uncertainty_sigmas)
        figures = {**decision.figures, "h1_seen_magnitude_db": mag_db,
                   "h1_seen_phase_deg": ph_deg}
        gross = err.n_points < acc.min_frf_points \
            or comp.gross(mag_db, ph_deg, snap.disagreement)
        return dataclasses.replace(decision, figures=figures, fault=gross)

    def _quiet(self, snap: Snapshot) -> str:
        """Why the windows of ``snap`` cannot judge a model (empty if they can): a
        reference, over a third of the window, both 20 dB below its usual level (its
        RMS over the windows of the channel's recent loads, ``snap.reference_level``:
        the 20 dB within which the band is taken from its spectrum) and so quiet that
        even a model that leaves the channel's usual residual (``snap.residual_floor``)
        would fit the feedback by less than the guard's ``min_fit_pct``: its RMS below
        ``floor / (1 − min_fit_pct / 100)``.

        Between tests, or once a record has died away, the stream goes on with next to
        nothing in the band: the H1 estimate confirms no point, the estimator drifts
        where nothing excites it, and every judgement failed as a fault. On the
        simulated rig, a record stopped at 20 s for 10 s alarmed 1.4 s into the pause.
        Refused as no fault, such windows keep the last good compensator and raise no
        alarm. A failing sensor is judged as before: it does not quieten the reference.
        Both conditions: the first alone would skip a coda's last seconds, where a
        stuck sensor is still told by its residual (:meth:`AdaptiveCompensator.
        _judge_fit`); the second alone every judgement of a loop whose sensor noise is
        10 % of its feedback, where no model fits by 90 %.
        """
        floor, usual = snap.residual_floor, snap.reference_level
        if floor is None or usual is None or snap.desired.size < 3:
            return ""
        min_fit = self.compensator.guard.acceptance.min_fit_pct
        need = min(floor / (1.0 - min_fit / 100.0), QUIET_REFERENCE * usual)
        # in each third of the window (the H1 estimate's segments): a window that a
        # pause ended or began in is no more use than a quiet one
        level = min(float(np.std(part)) for part in np.array_split(snap.desired, 3))
        if level >= need:
            return ""
        return (f"the reference is quiet ({level:.3g} RMS over a third of the window, "
                f"below {need:.3g}: 20 dB under its usual {usual:.3g}, and too little for "
                f"a model leaving the usual residual to fit the feedback by {min_fit:g} "
                "%): nothing to judge")

    def _against_running(self, decision: Decision, snap: Snapshot) -> Decision:
        """A model's compensator replaces the running one only if, replayed on the
        rows of ``snap.ran``, it would not have left more tracking error (by more than
        ``load_sigmas`` standard errors of the ratio, if set)."""
        assert decision.design is not None and snap.current is not None
        cmp = compare_compensators(decision.design, snap.current, snap.desired,
                                   snap.feedback, snap.ran, chunk=self._n_chunk)
        figures = {**decision.figures, "against_running": cmp.ratio,
                   "against_running_se": cmp.standard_error}
        sigmas = self.settings.load_sigmas
        limit = 1.0 + sigmas * cmp.standard_error if sigmas else 1.0
        if cmp.ratio > limit:
            return Decision(decision.t_s, False, f"the model's compensator would leave "
                            f"{cmp.ratio:.2f} of the running one's tracking error "
                            f"(at most {limit:.2f})", figures=figures, fault=False)
        return Decision(decision.t_s, True, "", decision.design, figures)


def seen_alike(model: ehss.ArmaxModel, h1: FrequencyResponse, u: np.ndarray, fresh: int
               ) -> FrequencyResponse:
    """``h1`` (of the rows of ``u`` from ``fresh`` on) with each point's averaging
    taken out as far as ``model`` is concerned: times ``M(f) / Ĥ_M(f)``, ``Ĥ_M`` the
    same estimate of the model's own output on the same rows (simulated from rest over
    all of ``u``), so that the model's response at a point is compared with the
    loop's as the estimate saw both.

    A point averages the response over its bin, weighted by the window's main lobe and
    the drive's spectrum there: at the band's edges, where the drive's spectrum falls
    to nothing within a bin, and in short segments, that average is not the response
    at the bin's centre. On the 12 Hz loop behind 2 ms of delay 0.75 s after +40 % mass
    (segments of 0.26 s), the point at 19.5 Hz of a 0.5–20 Hz drive was 16.4° off the
    refitted model, and 0.3° off it seen alike: the estimate of the model's own output
    through the same segments shows the same bias, and the ratio of the two estimates
    compares like with like. An unstable model, or one whose estimate has no power at a
    point, is left as it is."""
    if not model.is_stable():
        return h1
    with np.errstate(over="ignore", invalid="ignore"):
        y_m = model.simulate(u)[fresh:]
    if not np.all(np.isfinite(y_m)) or not np.any(y_m):
        return h1
    h1_m = ehss.h1_estimate(u[fresh:], y_m, fs=h1.fs, nperseg=h1.nperseg,
                            delay=h1.delay_samples)
    ok = np.abs(h1_m.response) > 0
    response = h1.response.copy()
    response[ok] *= model.frequency_response(h1.freq_hz[ok]) / h1_m.response[ok]
    return dataclasses.replace(h1, response=response)


def _start_up(model: ehss.ArmaxModel) -> int:
    """Samples after which ``model``, run from rest, has forgotten its start: its
    input's taps, and its slowest pole's decay (:func:`ehss._settle.decay_samples`)."""
    radius = float(np.max(np.abs(model.poles()), initial=0.0))
    return max(model.delay + model.b.size, decay_samples(radius))
