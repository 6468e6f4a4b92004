"""The filter a real-time target runs: a compensator, and bumpless swaps between them.

A **compensator** (:class:`Compensator`) is a cascade of second-order sections followed
by an FIR part, run with a fixed *preview*:

.. math:: u[k] = \\sum_{j=0}^{n_h-1} h_j\\, v[k-j], \\qquad
          v = \\Big(\\prod_{s} \\frac{b_{0s} + b_{1s} z^{-1} + b_{2s} z^{-2}}
                                    {1 + a_{1s} z^{-1} + a_{2s} z^{-2}}\\Big)\\, r_p,
          \\qquad r_p[k] = r[k + p]

so the filter's input at step ``k`` is the reference ``p`` samples ahead, ``r[k + p]``,
and its output is the drive at step ``k``. The sections are in scipy's ``sos`` layout
(rows ``b0 b1 b2 a0 a1 a2``, ``a0 = 1``) and run in direct form II transposed, as
:func:`scipy.signal.sosfilt` runs them; ``taps`` may be ``[1.0]`` (no FIR part). Every
section must be stable (its poles strictly inside the unit circle: ``|a2| < 1`` and
``|a1| < 1 + a2``): a target must not run a filter that can diverge.

The state has a fixed size, shared with the C code (``c/ehss_compensator.h``):
at most :data:`MAX_SECTIONS` sections and :data:`MAX_TAPS` taps, and a preview of at most
``MAX_TAPS - 1`` samples, so that "no compensation" (a pure delay of ``p`` samples,
:meth:`Compensator.delay`) is always a compensator the filter can run.

**Swapping.** :meth:`CompensatorFilter.load` hands over a new compensator, the sample
index ``k0`` from which it applies and a cross-fade length ``N``. The new filter is taken
up at the next sample boundary where no cross-fade is under way (a load that arrives
during a cross-fade waits for its end; while one waits, a further load is refused as
``busy``, as the C target's one-slot mailbox refuses it, and the host sends it again).
It replaces a filter still in shadow (counted ``superseded``). From then on it runs
*in shadow*, beside the running one, on the same input;
from sample ``k0`` the drive is

.. math:: u[k] = (1 - w_k)\\, u_{old}[k] + w_k\\, u_{new}[k], \\qquad
          w_k = \\frac{k - k_0 + 1}{N}, \\quad k_0 \\le k < k_0 + N,

and after sample ``k0 + N - 1`` (where ``w = 1``) the old filter is dropped; ``N = 0``
and ``N = 1`` both switch at ``k0`` outright.

*How the new filter's state starts.* At zero, when it is taken up, and it then runs in
shadow until ``k0``. Loaded far enough ahead (the host schedules ``k0`` at least the new
compensator's settling time after sending it), its start-up transient has decayed
before it contributes to the drive: its output is then exactly what it would be had it
run from the start, and the cross-fade blends two steady outputs. Starting instead from
a state that gives the same output as the old filter is not possible in general: the
two filters have different orders and dynamics, and matching one output sample (or a
few) does not make the following ones match, so such a start would still leave a
transient, of unknown size. So a compensator always runs in shadow for its settling
time (:attr:`Compensator.settle_samples`): one taken up too late for that before
``k0`` (the datagram came late, or waited for a cross-fade to end) starts its
cross-fade that long after it was taken up, not at ``k0``, and is counted ``late``.
Fading in an unsettled filter would put its start-up transient, as large as the
reference, into the drive.

A compensator with a different preview than the running one is refused and counted:
the drive would jump by the difference of the previews. So is one designed for a sample
rate more than :data:`SAMPLE_RATE_TOLERANCE` (0.1 %) away from the filter's: its time
constants and delays would be misplaced by as much (a model identified on a decimated
record, say, has a rate several times lower).

Examples
--------
>>> f = CompensatorFilter(Compensator.delay(0, fs_hz=1000.0))
>>> f.load(Compensator(sos=[[0.5, 0, 0, 1, 0, 0]], taps=[1.0], preview=0, fs_hz=1000.0),
...        apply_index=2, crossfade=4)
True
>>> f.process(np.ones(8)).tolist()
[1.0, 1.0, 0.875, 0.75, 0.625, 0.5, 0.5, 0.5]
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ehss._checks import SAMPLE_RATE_RANGE_HZ, as_signal, check_int, check_real
from ehss._settle import settle_samples
from ehss.errors import ParameterError
from ehss.target._kernels import crossfade_block, filter_block

__all__ = [
    "MAX_SECTIONS",
    "MAX_TAPS",
    "MAX_PREVIEW",
    "SAMPLE_RATE_TOLERANCE",
    "Compensator",
    "CompensatorFilter",
    "coefficient_fault",
]

#: Most second-order sections of one compensator (the C state's size, too).
MAX_SECTIONS = 16
#: Most FIR taps of one compensator (the C state's size, too): 0.41 s at 5 kHz; the
#: 0.256 s that :func:`ehss.compensation.compensator_design.fir_taps` asks, up to 8 kHz.
MAX_TAPS = 2048
#: Longest preview, samples: a pure delay of it fits the FIR part.
MAX_PREVIEW = MAX_TAPS - 1
#: Largest relative difference between a loaded compensator's sample rate and the
#: filter's (the C code's ``EHSS_COMP_SAMPLE_RATE_TOLERANCE``).
SAMPLE_RATE_TOLERANCE = 1e-3


def coefficient_fault(sos: np.ndarray, taps: np.ndarray) -> str | None:
    """Why ``sos`` (shape (n, 6)) and ``taps`` (shape (m,)) cannot run, or None.

    The kinds, in the order they are checked (the C decoder checks the same):
    ``"sections"`` (n outside 0..MAX_SECTIONS), ``"taps"`` (m outside 1..MAX_TAPS),
    ``"non_finite"``, ``"not_normalised"`` (a section's ``a0`` is not 1) and
    ``"unstable"`` (a section has a pole on or outside the unit circle).
    """
    if not 0 <= sos.shape[0] <= MAX_SECTIONS:
        return "sections"
    if not 1 <= taps.shape[0] <= MAX_TAPS:
        return "taps"
    if not (np.isfinite(sos).all() and np.isfinite(taps).all()):
        return "non_finite"
    if (sos[:, 3] != 1.0).any():
        return "not_normalised"
    a1, a2 = sos[:, 4], sos[:, 5]
    # poles of z^2 + a1 z + a2 strictly inside |z| = 1  <=>  |a2| < 1 and |a1| < 1 + a2
    if ((np.abs(a2) >= 1.0) | (np.abs(a1) >= 1.0 + a2)).any():
        return "unstable"
    return None


_FAULT_TEXT = {
    "sections": f"must have shape (n_sections, 6) with n_sections <= {MAX_SECTIONS}",
    "taps": f"must hold 1 to {MAX_TAPS} taps (use [1.0] for no FIR part)",
    "non_finite": "must be finite",
    "not_normalised": "must have a0 = 1 in every section (divide the section by its a0)",
    "unstable": "must have every section's poles strictly inside the unit circle "
                "(|a2| < 1 and |a1| < 1 + a2)",
}


def _as_matrix(value: Any, name: str, columns: int | None) -> np.ndarray:
    try:
        a = np.array(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ParameterError(f"{name} must be an array of numbers, not {exc}") from None
    if columns is not None:
        if a.size == 0:
            a = a.reshape(0, columns)
        if a.ndim != 2 or a.shape[1] != columns:
            raise ParameterError(f"{name} has shape {a.shape}, must be (n_sections, 6)")
    elif a.ndim != 1:
        raise ParameterError(f"{name} has shape {a.shape}, must be 1-D")
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class Compensator:
    """One channel's compensator, as a target runs it (see the module notes).

    Parameters
    ----------
    sos : array_like, shape (n_sections, 6)
        Second-order sections, scipy's layout, ``a0 = 1``, each stable;
        ``0 <= n_sections <= MAX_SECTIONS``.
    taps : array_like, shape (n_taps,)
        FIR part after the sections, ``1 <= n_taps <= MAX_TAPS``; ``[1.0]`` for none
        (an empty sequence is read as ``[1.0]``).
    preview : int
        Samples of reference known ahead, ``0 <= preview <= MAX_PREVIEW``; 0 is causal.
    fs_hz : float
        Sample rate of the model the compensator was designed from, Hz.

    Raises
    ------
    ParameterError
        If a coefficient array has the wrong shape or size, a coefficient is not
        finite, a section is not normalised or not stable, or ``preview`` / ``fs_hz``
        is out of range.
    """

    sos: np.ndarray
    taps: np.ndarray
    preview: int
    fs_hz: float

    def __post_init__(self) -> None:
        sos = _as_matrix(self.sos, "sos", 6)
        taps = _as_matrix(self.taps, "taps", None)
        if taps.size == 0:
            taps = _as_matrix([1.0], "taps", None)
        fault = coefficient_fault(sos, taps)
        if fault is not None:
            what = "taps" if fault == "taps" else "sos" if fault != "non_finite" else \
                "sos and taps"
            raise ParameterError(f"{what} {_FAULT_TEXT[fault]}; got sos of shape "
                                 f"{sos.shape} and {taps.size} taps")
        object.__setattr__(self, "sos", sos)
        object.__setattr__(self, "taps", taps)
        object.__setattr__(self, "preview", check_int(self.preview, "preview", lo=0,
                                                      hi=MAX_PREVIEW))
        lo, hi = SAMPLE_RATE_RANGE_HZ
        object.__setattr__(self, "fs_hz", check_real(self.fs_hz, "fs_hz", lo=lo, hi=hi,
                                                     unit="Hz"))

    @classmethod
    def delay(cls, preview: int, *, fs_hz: float) -> Compensator:
        """No compensation with ``preview`` samples ahead: the drive is the reference,
        ``u[k] = r[k]``, i.e. the input delayed by ``preview`` samples."""
        p = check_int(preview, "preview", lo=0, hi=MAX_PREVIEW)
        taps = np.zeros(p + 1)
        taps[p] = 1.0
        return cls(sos=np.zeros((0, 6)), taps=taps, preview=p, fs_hz=fs_hz)

    @property
    def n_sections(self) -> int:
        return int(self.sos.shape[0])

    @property
    def n_taps(self) -> int:
        return int(self.taps.shape[0])

    @property
    def settle_samples(self) -> int:
        """Samples it runs in shadow, from rest, before its output is what it would
        be had it run all along (:func:`ehss._settle.settle_samples`)."""
        return settle_samples(self.sos, self.n_taps)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Compensator):
            return NotImplemented
        return (self.preview == other.preview and self.fs_hz == other.fs_hz
                and np.array_equal(self.sos, other.sos)
                and np.array_equal(self.taps, other.taps))

    __hash__ = None  # type: ignore[assignment]


class _Slot:
    """One running filter: a compensator's coefficients in fixed-size arrays, and state."""

    def __init__(self, compensator: Compensator) -> None:
        self.compensator = compensator
        self.n_sections = compensator.n_sections
        self.n_taps = compensator.n_taps
        self.sos = np.zeros((MAX_SECTIONS, 6))
        self.sos[: self.n_sections] = compensator.sos
        self.taps = np.zeros(MAX_TAPS)
        self.taps[: self.n_taps] = compensator.taps
        self.z = np.zeros((MAX_SECTIONS, 2))    # every state starts at zero
        self.hist = np.zeros(MAX_TAPS)
        self.pos = 0

    def run(self, x: np.ndarray) -> np.ndarray:
        y = np.empty_like(x)
        self.pos = filter_block(self.sos, self.n_sections, self.z, self.taps, self.n_taps,
                                self.hist, self.pos, x, y)
        return y


@dataclass(frozen=True)
class _Load:
    compensator: Compensator
    apply_index: int
    crossfade: int


COUNTERS = ("loads", "swaps", "refused_preview", "refused_sample_rate", "busy", "superseded",
            "late")
# why a load is refused -> its counter
_REFUSED = {"other_preview": "refused_preview", "other_sample_rate": "refused_sample_rate"}


def _as_block(block: Any) -> np.ndarray:
    """``block`` as a finite float64 1-D array: the common case checked in a few
    microseconds, the rest by :func:`~ehss._checks.as_signal` (which names the bad
    sample)."""
    try:
        x = np.ascontiguousarray(block, dtype=np.float64)
    except (TypeError, ValueError):
        x = None
    if x is None or x.ndim != 1 or not np.isfinite(x).all():
        x = as_signal(block, "block", allow_empty=True)
    return x


class CompensatorFilter:
    """The target-side filter of one channel, with bumpless compensator swaps.

    Parameters
    ----------
    initial : Compensator
        The compensator that runs from the start; its preview and sample rate are the
        filter's for good (:meth:`Compensator.delay` runs the reference unchanged).
    start_index : int, default 0
        Sample index of the first sample :meth:`step` or :meth:`process` computes.

    Attributes
    ----------
    counters : dict of str to int
        ``loads`` (taken up), ``swaps`` (cross-fades completed), ``refused_preview``,
        ``refused_sample_rate``, ``busy`` (refused while another load waited),
        ``superseded`` (replaced by a newer load while still in shadow), ``late`` (taken
        up too late to settle by their apply index: the cross-fade started their
        settling time after they were taken up).
    """

    def __init__(self, initial: Compensator, *, start_index: int = 0) -> None:
        if not isinstance(initial, Compensator):
            raise TypeError(f"initial must be a Compensator, not {type(initial).__name__}")
        self._run = _Slot(initial)
        self._preview = initial.preview
        self._fs_hz = initial.fs_hz
        self._next: _Slot | None = None
        self._start = 0          # k0 of the next filter
        self._crossfade = 0      # N of the next filter
        self._pending: _Load | None = None
        self._index = check_int(start_index, "start_index", lo=0)
        self.counters = dict.fromkeys(COUNTERS, 0)

    @property
    def preview(self) -> int:
        """Samples of reference the input runs ahead of the drive."""
        return self._preview

    @property
    def fs_hz(self) -> float:
        """Sample rate the filter runs at, Hz (the initial compensator's)."""
        return self._fs_hz

    def accepts(self, compensator: Compensator) -> str | None:
        """Why :meth:`load` would refuse ``compensator`` (``"other_preview"``,
        ``"other_sample_rate"``), or None."""
        if compensator.preview != self._preview:
            return "other_preview"
        # |fs - fs_0| > tol fs_0, as the C code computes it
        if abs(compensator.fs_hz - self._fs_hz) > SAMPLE_RATE_TOLERANCE * self._fs_hz:
            return "other_sample_rate"
        return None

    @property
    def index(self) -> int:
        """Sample index of the next drive sample."""
        return self._index

    @property
    def active(self) -> Compensator:
        """The compensator that runs (the old one, while a cross-fade is under way)."""
        return self._run.compensator

    @property
    def incoming(self) -> Compensator | None:
        """The compensator running in shadow or fading in, if any."""
        return None if self._next is None else self._next.compensator

    @property
    def waiting(self) -> bool:
        """True while a load waits to be taken up (during a cross-fade)."""
        return self._pending is not None

    def load(self, compensator: Compensator, apply_index: int, crossfade: int) -> bool:
        """Hand over ``compensator``, to apply from sample ``apply_index`` with a
        cross-fade of ``crossfade`` samples.

        It is taken up at the next sample boundary where no cross-fade is under way,
        replacing a filter still in shadow.

        Returns
        -------
        bool
            False, and counted, if it is refused: its preview differs from the filter's
            (``refused_preview``), its sample rate is more than
            :data:`SAMPLE_RATE_TOLERANCE` away from the filter's (``refused_sample_rate``)
            or another load still waits (``busy``).
        """
        if not isinstance(compensator, Compensator):
            raise TypeError(f"compensator must be a Compensator, not "
                            f"{type(compensator).__name__}")
        k0 = check_int(apply_index, "apply_index", lo=0)
        n = check_int(crossfade, "crossfade", lo=0)
        refused = self.accepts(compensator)
        if refused is not None:
            self.counters[_REFUSED[refused]] += 1
            return False
        if self._pending is not None:
            self.counters["busy"] += 1
            return False
        self._pending = _Load(compensator, k0, n)
        return True

    def _fading(self) -> bool:
        return self._next is not None and self._index >= self._start

    def _take_pending(self) -> None:
        """At a sample boundary outside a cross-fade: the waiting load starts in shadow."""
        if self._pending is None or self._fading():
            return
        if self._next is not None:
            self.counters["superseded"] += 1
        load, self._pending = self._pending, None
        self._next = _Slot(load.compensator)
        settled = self._index + load.compensator.settle_samples
        self._start = max(load.apply_index, settled)
        self._crossfade = load.crossfade
        self.counters["loads"] += 1
        self.counters["late"] += load.apply_index < settled

    def _segment(self, room: int) -> int:
        """Samples from the current one until the next event (at most ``room``)."""
        if self._next is None:
            return room
        if self._index < self._start:   # shadow until the cross-fade starts
            return min(room, self._start - self._index)
        end = self._start + max(self._crossfade, 1)   # the cross-fade's end
        return min(room, end - self._index)

    def _advance(self, x: np.ndarray) -> np.ndarray:
        """Run the samples ``x`` of one segment (no event inside it)."""
        y = self._run.run(x)
        new = self._next
        if new is None:
            self._index += x.size
            return y
        y_new = new.run(x)
        if self._index >= self._start:   # fading in
            n = max(self._crossfade, 1)
            # w_k = (k - k0 + 1) / N ;  u = (1 - w) u_old + w u_new
            crossfade_block(y, y_new, self._index - self._start + 1, n)
            if self._index + x.size >= self._start + n:   # w reached 1: drop the old one
                self._run, self._next = new, None
                self.counters["swaps"] += 1
        self._index += x.size
        return y

    def process(self, block: Any) -> np.ndarray:
        """Drive samples for the input samples ``block`` (the reference ``preview``
        samples ahead), sample by sample exactly as :meth:`step` and the C code.

        Parameters
        ----------
        block : array_like, shape (n,)
            Finite samples.

        Returns
        -------
        ndarray, shape (n,)

        Raises
        ------
        DataError
            If ``block`` is not 1-D or holds a NaN or infinite sample (it would stay in
            the filter's state for good); the filter is left as it was.
        """
        x = _as_block(block)
        out = np.empty_like(x)
        i = 0
        while i < x.size:
            self._take_pending()
            m = self._segment(x.size - i)
            out[i:i + m] = self._advance(x[i:i + m])
            i += m
        return out

    def step(self, x: float) -> float:
        """The drive sample for one input sample ``x``."""
        return float(self.process(np.array([x], dtype=np.float64))[0])
