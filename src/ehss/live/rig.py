"""The simulated rig as a live source: several channels, scheduled parameter changes.

Two forms: :func:`rig_record`, the whole record computed up front, and
:class:`SteppingRig`, the rig run block by block as a target runs it, with each
channel's drive computed online by the target's compensator filter.

:func:`rig_record` builds the whole schedule up front with :func:`ehss.simulate` (the
whole-record kernel, several hundred times faster than real time) and the caller plays
it to the wall clock (:class:`~ehss.live.source.PacedSource`) or sends it over UDP
(``ehss stream``). Each channel is one actuator loop with its own reference and sensor
noise (seeds ``seed + k``). An event changes a parameter of one channel, or of all, from
its time on: the record is simulated in pieces between events, each piece with the new
:class:`~ehss.params.RigParams` (``dataclasses.replace``) and continuing from the full
state at the end of the previous piece (:class:`ehss.simulation.SimulationState`: plant,
controller, delay line and sensor noise), so that the controller runs on through an
event as it would on a real rig.
"""

from __future__ import annotations

import dataclasses
import math
import re
from dataclasses import dataclass
from typing import Any

import numpy as np

import ehss
from ehss.errors import ParameterError
from ehss.live.layout import RecordLayout

__all__ = ["RigEvent", "parse_event", "rig_record", "rig_reference", "rig_layout", "RIG_SIGNAL",
           "RIG_COMPENSATE_SIGNAL",
           "FAULT_KINDS",
           "RigFault", "RigBlock", "SteppingRig"]

#: Reference of each loop on the live rig: (RMS in SI units, band in Hz). The band
#: reaches past the hydraulic resonance so that a change of the load shows in the data.
RIG_SIGNAL = {
    "position": (1.0e-3, (1.0, 50.0)),
    "acceleration": (0.5, (1.0, 50.0)),
    "force": (1000.0, (1.0, 50.0)),
}
#: The reference of each loop when ``ehss live --rig`` compensates it (``--compensate``):
#: the position loop's 1 mm over 1–50 Hz asks for drives 3.9× the reference's RMS and
#: beyond the rig's 0.2 m/s, so that every update would be refused; over 0.5–20 Hz at
#: 0.5 mm its inverse is loaded and tracks 64× better (12 s, seed 0). Below about 3 Hz
#: the acceleration loop's response is shaped by its 0.5 Hz high-passes (the
#: acceleration generator, the accelerometer's coupling), which the online sixth-order
#: model misses by 3–5 dB / 8–25° at 1 Hz and by less than the guard's 1 dB / 5° from
#: 3 Hz; over 3–50 Hz it tracks 11–21× better than without, over 1–50 Hz 5.5–9.7× (30 s,
#: seeds 0–2, second half).
RIG_COMPENSATE_SIGNAL = {**RIG_SIGNAL, "position": (5.0e-4, (0.5, 20.0)),
                         "acceleration": (0.5, (3.0, 50.0))}
#: Fade in and out of the rig's reference at each end (s): it starts and ends at rest.
RIG_FADE_S = 0.2

_EVENT = re.compile(
    r"^\s*(?P<t>[0-9.eE+-]+)\s*:\s*(?P<name>[A-Za-z_][A-Za-z0-9_.]*)\s*=\s*"
    r"(?P<value>[0-9.eE+-]+)\s*(?:@\s*(?P<ch>\w+))?\s*$"
)


@dataclass(frozen=True)
class RigEvent:
    """A parameter change of the simulated rig.

    Attributes
    ----------
    time_s : float
        When it happens (s from the start).
    path : str
        ``group.field`` of :class:`~ehss.params.RigParams` (e.g. ``load.mass_kg``).
    value : float
    channel : str or None
        Channel it applies to (None: every channel).
    """

    time_s: float
    path: str
    value: float
    channel: str | None = None


def _resolve(name: str) -> str:
    """``mass_kg`` → ``load.mass_kg``; a dotted path is checked as given."""
    params = ehss.preset("default")
    groups = [f.name for f in dataclasses.fields(params)
              if dataclasses.is_dataclass(getattr(params, f.name))]
    if "." in name:
        group, leaf = name.split(".", 1)
        if group in groups and leaf in {f.name for f in dataclasses.fields(getattr(params,
                                                                                    group))}:
            return name
        raise ParameterError(f"unknown rig parameter {name!r}")
    hits = [f"{g}.{name}" for g in groups
            if name in {f.name for f in dataclasses.fields(getattr(params, g))}]
    if len(hits) != 1:
        raise ParameterError(
            f"rig parameter {name!r} is " + ("unknown" if not hits else
                                             f"ambiguous ({', '.join(hits)})")
            + "; give it as group.field, e.g. load.mass_kg"
        )
    return hits[0]


def parse_event(text: str) -> RigEvent:
    """``"30:mass_kg=350"`` (every channel) or ``"30:valve.rated_flow_l_min=30@2"``.

    Raises
    ------
    ParameterError
        If the text is not ``T:NAME=VALUE[@CHANNEL]`` or names no rig parameter.
    """
    m = _EVENT.match(text) if isinstance(text, str) else None
    if m is None:
        raise ParameterError(
            f"event {text!r} must be T:NAME=VALUE[@CHANNEL], e.g. 30:mass_kg=350@1"
        )
    try:
        t, value = float(m["t"]), float(m["value"])
    except ValueError:
        raise ParameterError(f"event {text!r}: time and value must be numbers") from None
    if not (math.isfinite(t) and t >= 0 and math.isfinite(value)):
        raise ParameterError(f"event {text!r}: time must be >= 0 and the value finite")
    return RigEvent(t, _resolve(m["name"]), value, m["ch"])


def rig_layout(n_channels: int) -> RecordLayout:
    """``t, ref1, fb1, …, ref<n>, fb<n>``."""
    if not isinstance(n_channels, int) or not 1 <= n_channels <= 64:
        raise ParameterError(f"channels={n_channels!r} must be an integer in 1..64")
    names = ["t"]
    for k in range(1, n_channels + 1):
        names += [f"ref{k}", f"fb{k}"]
    return RecordLayout(tuple(names))


def _apply(params: ehss.RigParams, event: RigEvent) -> ehss.RigParams:
    group, leaf = event.path.split(".", 1)
    try:
        sub = dataclasses.replace(getattr(params, group), **{leaf: event.value})
        return dataclasses.replace(params, **{group: sub})
    except (TypeError, ValueError) as exc:
        raise ParameterError(f"event {event.path}={event.value!r}: {exc}") from None


def rig_reference(n: int, fs: float, *, band_hz: tuple[float, float], rms: float,
                  seed: int) -> np.ndarray:
    """One channel's reference on the live rig: band-limited random noise of ``n``
    samples, faded in and out over :data:`RIG_FADE_S`."""
    return ehss.signals.band_limited_random(band_hz=band_hz, rms=rms, duration_s=n / fs,
                                            fs=fs, seed=seed, fade_s=RIG_FADE_S).values[:n]


def _check_duration(duration_s: Any, fs: float) -> None:
    """A rig record's length: finite, long enough for its fades, short enough to hold."""
    if not (isinstance(duration_s, (int, float)) and math.isfinite(duration_s)
            and duration_s > 0):
        raise ParameterError(f"duration_s={duration_s!r} must be > 0")
    if duration_s < 2 * RIG_FADE_S:
        raise ParameterError(f"duration_s={duration_s!r} is too short: the rig's reference "
                             f"fades in and out over {RIG_FADE_S:g} s at each end, so at "
                             f"least {2 * RIG_FADE_S:g} s")
    if duration_s * fs > ehss.signals.MAX_SAMPLES:
        raise ParameterError(
            f"duration_s={duration_s!r} at fs={fs!r} gives {duration_s * fs:.3g} samples; at "
            f"most {ehss.signals.MAX_SAMPLES} are allowed (split the test into shorter "
            "records)")


def rig_record(
    loop: str, *, n_channels: int, duration_s: float, fs: float | None = None,
    params: ehss.RigParams | None = None, events: tuple[RigEvent, ...] = (),
    seed: int = 0, rms: float | None = None, band_hz: tuple[float, float] | None = None,
) -> tuple[RecordLayout, np.ndarray, float]:
    """The whole live record of the simulated rig: ``(layout, samples, fs)``.

    Parameters
    ----------
    loop : {"position", "acceleration", "force"}
    n_channels : int
        Number of actuators (channels 1..n).
    duration_s : float
    fs : float, optional
        Control rate (default the parameter set's).
    params : RigParams, optional
        The rig (default preset "default").
    events : tuple of RigEvent
        Parameter changes; each applies from its time on (to its channel, or all).
    seed : int
        Channel k uses seed ``seed + k`` for its reference and ``seed + 1000 + k`` for
        its sensor noise.
    rms, band_hz : optional
        Reference RMS and band (default :data:`RIG_SIGNAL`).

    Returns
    -------
    layout : RecordLayout
    samples : ndarray, shape (n, 1 + 2 n_channels)
    fs : float
    """
    if loop not in RIG_SIGNAL:
        raise ParameterError(f"loop={loop!r} must be one of {sorted(RIG_SIGNAL)}")
    layout = rig_layout(n_channels)
    params = ehss.preset("default") if params is None else params
    fs = params.timing.control_rate_hz if fs is None else float(fs)
    _check_duration(duration_s, fs)
    d_rms, d_band = RIG_SIGNAL[loop]
    rms = d_rms if rms is None else rms
    band_hz = d_band if band_hz is None else band_hz
    n = int(round(duration_s * fs))
    for ev in events:
        if ev.channel is not None and ev.channel not in layout.channels:
            raise ParameterError(f"event on channel {ev.channel!r}: the rig has channels "
                                 f"{', '.join(layout.channels)}")
    out = np.empty((n, layout.n_fields))
    out[:, 0] = np.arange(n) / fs
    for k, ch in enumerate(layout.channels, start=1):
        ref = rig_reference(n, fs, band_hz=band_hz, rms=rms, seed=seed + k)
        mine = sorted((e for e in events if e.channel in (None, ch)), key=lambda e: e.time_s)
        cuts = sorted({min(n, int(round(e.time_s * fs))) for e in mine} - {0, n})
        p = params
        for e in mine:
            if int(round(e.time_s * fs)) <= 0:
                p = _apply(p, e)
        y = np.empty(n)
        state = None
        bounds = [0, *cuts, n]
        for a, b in zip(bounds[:-1], bounds[1:], strict=True):
            for e in mine:
                if a > 0 and int(round(e.time_s * fs)) == a:
                    p = _apply(p, e)
            run = ehss.simulate(loop, ref[a:b], params=p, fs=fs,
                                seed=seed + 1000 + k if state is None else None,
                                initial_state=state)
            y[a:b] = run.output
            state = run.final_state
        out[:, layout.ref_index[k - 1]] = ref
        out[:, layout.fb_index[k - 1]] = y
    return layout, out, fs


# ----------------------------------------------------------------------------- stepping
#: Faults of the feedback a channel reports (the acquisition's, not the loop's):
#: ``sign`` (wired inverted), ``stuck`` (held at its value when the fault starts),
#: ``noise`` (a burst of white noise, ``value`` × the reference's RMS).
FAULT_KINDS = ("sign", "stuck", "noise")


@dataclass(frozen=True)
class RigFault:
    """A fault of the feedback one channel reports, from ``start_s`` to ``end_s``.

    Attributes
    ----------
    start_s, end_s : float
    kind : {"sign", "stuck", "noise"}
    channel : str
    value : float
        For ``noise``: RMS of the burst as a multiple of the reference's RMS.
    """

    start_s: float
    end_s: float
    kind: str
    channel: str
    value: float = 1.0

    def __post_init__(self) -> None:
        if self.kind not in FAULT_KINDS:
            raise ParameterError(f"fault kind={self.kind!r} must be one of {FAULT_KINDS}")
        if not (math.isfinite(self.start_s) and self.end_s > self.start_s >= 0):
            raise ParameterError(f"fault from {self.start_s!r} to {self.end_s!r} s: need "
                                 "0 <= start_s < end_s")


@dataclass(frozen=True)
class RigBlock:
    """Consecutive samples of a :class:`SteppingRig`, each array shape (n_channels, n).

    Attributes
    ----------
    first_index : int
    desired : ndarray
        The reference the table should follow.
    drive : ndarray
        The reference the loop received (the compensator's output; the model's input).
    feedback : ndarray
        The measured feedback as reported (with any :class:`RigFault`).
    """

    first_index: int
    desired: np.ndarray
    drive: np.ndarray
    feedback: np.ndarray


class SteppingRig:
    """The simulated rig run block by block, as a real-time target would run it.

    Each channel is one closed loop (:func:`ehss.simulate`, continued from its
    :class:`~ehss.simulation.SimulationState` block after block: plant, controller,
    delay line and noise carry over). Its drive is computed online from the desired
    reference by the channel's :class:`ehss.target.filter.CompensatorFilter` (the filter
    the C target runs), which reads the reference ``preview`` samples ahead; until a
    compensator is loaded the drive is the reference. Events (:class:`RigEvent`) apply
    between blocks, at their sample, without restarting anything.

    Parameters
    ----------
    loop : {"position", "acceleration", "force"}
    desired : ndarray, shape (n_channels, n)
        Desired reference of each channel (the whole test, known ahead in preview mode;
        a causal compensator reads only the present).
    fs : float
    params : RigParams, optional
    events : tuple of RigEvent
    faults : tuple of RigFault
    preview : int
        Samples of reference each filter reads ahead (0: causal).
    seed : int
        Channel k's sensor noise has seed ``seed + 1000 + k`` (as :func:`rig_record`).
    channels : tuple of str, optional
        Channel names (default "1", "2", ...).
    """

    def __init__(self, loop: str, desired: np.ndarray, *, fs: float,
                 params: ehss.RigParams | None = None, events: tuple[RigEvent, ...] = (),
                 faults: tuple[RigFault, ...] = (), preview: int = 0, seed: int = 0,
                 channels: tuple[str, ...] | None = None) -> None:
        from ehss.target.filter import Compensator, CompensatorFilter

        if loop not in RIG_SIGNAL:
            raise ParameterError(f"loop={loop!r} must be one of {sorted(RIG_SIGNAL)}")
        desired = np.atleast_2d(np.asarray(desired, dtype=float))
        self.loop, self.fs = loop, float(fs)
        self.desired = desired
        self.n_channels, self.n_samples = desired.shape
        self.channels = channels or tuple(str(k) for k in range(1, self.n_channels + 1))
        base = ehss.preset("default") if params is None else params
        self.params = [base] * self.n_channels
        self.events = tuple(sorted(events, key=lambda e: e.time_s))
        self.faults = tuple(faults)
        named = [e.channel for e in self.events] + [f.channel for f in self.faults]
        for channel in named:
            if channel is not None and channel not in self.channels:
                raise ParameterError(f"channel {channel!r}: the rig has channels "
                                     f"{', '.join(self.channels)}")
        self.preview = int(preview)
        self.filters = [CompensatorFilter(Compensator.delay(self.preview, fs_hz=self.fs))
                        for _ in range(self.n_channels)]
        # the reference known ahead is known from the start: the filters read its first
        # `preview` samples before the first drive sample, whose index is then `preview`
        # in the filter's count (what load() translates)
        for ch, f in enumerate(self.filters):
            f.process(desired[ch, :min(self.preview, self.n_samples)])
        self._seeds = [seed + 1000 + k for k in range(1, self.n_channels + 1)]
        self._states: list = [None] * self.n_channels
        self._stuck = [0.0] * self.n_channels
        self._rng = np.random.default_rng(seed + 7)
        self._ref_rms = np.sqrt(np.mean(desired**2, axis=1))
        self.index = 0

    @property
    def finished(self) -> bool:
        return self.index >= self.n_samples

    def load(self, channel: int, compensator: Any, apply_index: int, crossfade: int) -> bool:
        """Hand a compensator to channel ``channel``'s filter, to apply from the drive
        sample ``apply_index`` (see :meth:`ehss.target.filter.CompensatorFilter.load`)."""
        return self.filters[channel].load(compensator, apply_index + self.preview, crossfade)

    def _events_at(self, k: int) -> None:
        for e in self.events:
            if int(round(e.time_s * self.fs)) == k:
                for c, name in enumerate(self.channels):
                    if e.channel in (None, name):
                        self.params[c] = _apply(self.params[c], e)

    def _next_cut(self, a: int, b: int) -> int:
        for e in self.events:
            k = int(round(e.time_s * self.fs))
            if a < k < b:
                return k
        return b

    def step(self, n: int) -> RigBlock:
        """Run the next ``n`` samples (fewer at the end); events apply at their sample."""
        a = self.index
        b = min(self.n_samples, a + int(n))
        c = self.n_channels
        drive = np.empty((c, b - a))
        fb = np.empty((c, b - a))
        k = a
        while k < b:
            self._events_at(k)
            end = self._next_cut(k, b)
            ahead = np.arange(k, end) + self.preview
            for ch in range(c):
                # the filter's input: the reference `preview` samples ahead (held at its
                # last value past the end of the test)
                x = self.desired[ch, np.minimum(ahead, self.n_samples - 1)]
                u = self.filters[ch].process(x)
                first = self._states[ch] is None
                run = ehss.simulate(self.loop, u, params=self.params[ch], fs=self.fs,
                                    seed=self._seeds[ch] if first else None,
                                    initial_state=self._states[ch])
                self._states[ch] = run.final_state
                drive[ch, k - a:end - a] = u
                fb[ch, k - a:end - a] = run.output
            k = end
        self._apply_faults(a, fb)
        self.index = b
        return RigBlock(a, self.desired[:, a:b].copy(), drive, fb)

    def _apply_faults(self, a: int, fb: np.ndarray) -> None:
        n = fb.shape[1]
        for f in self.faults:
            ch = self.channels.index(f.channel)
            i0 = max(0, int(round(f.start_s * self.fs)) - a)
            i1 = min(n, int(round(f.end_s * self.fs)) - a)
            if i1 <= i0:
                continue
            if f.kind == "sign":
                fb[ch, i0:i1] = -fb[ch, i0:i1]
            elif f.kind == "stuck":
                if a + i0 == int(round(f.start_s * self.fs)):
                    self._stuck[ch] = fb[ch, i0]
                fb[ch, i0:i1] = self._stuck[ch]
            else:
                fb[ch, i0:i1] += f.value * self._ref_rms[ch] * \
                    self._rng.standard_normal(i1 - i0)
