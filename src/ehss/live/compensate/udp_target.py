"""A remote target over UDP (:class:`UdpTarget`), and the sender of its compensators
(:class:`DatagramSender`).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ehss.errors import ParameterError

#: How long after the second compensator sent to it should have been faded in a target's
#: drive may still be its desired reference, unchanged since the first one's apply
#: index, before the target is taken to refuse them, s. One missed compensator is not
#: enough: a datagram that reached the target late (a host or a target that lost the
#: processor for a while) is taken up late, and a second one may replace it before it
#: was faded in.
IGNORED_AFTER_S = 0.5
#: The same when no second compensator was sent: from the first one's fade-in, s.
IGNORED_LONE_S = 2.0


class DatagramSender:
    """Sends compensators to a remote target, one :mod:`ehss.target.datagram` each.

    Parameters
    ----------
    address : (host, port)
        The target's compensator port.
    first_sequence : int, optional
        Sequence number of the first datagram (default: the Unix time in ms, so that a
        restarted host keeps numbering upwards).
    """

    def __init__(self, address: tuple[str, int], *, first_sequence: int | None = None) -> None:
        import socket

        self.address = (str(address[0]), int(address[1]))
        self.sequence = int(time.time() * 1000) if first_sequence is None \
            else int(first_sequence)
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sent = 0

    def send(self, channel: int, compensator: Any, apply_index: int, crossfade: int) -> bool:
        """Encode and send one update; True once sent (the target may still refuse it)."""
        from ehss.target.datagram import CompensatorUpdate, encode

        update = CompensatorUpdate(channel=channel, sequence=self.sequence,
                                   apply_index=int(apply_index), crossfade=int(crossfade),
                                   compensator=compensator)
        self._sock.sendto(encode(update), self.address)
        self.sequence += 1
        self.sent += 1
        return True

    def close(self) -> None:
        self._sock.close()


def _passes_reference(compensator: Any) -> bool:
    """Whether ``compensator`` gives the drive = the reference (its impulse response a
    unit at its preview), as a target runs before any compensator or with compensation
    switched off (:func:`~ehss.compensation.compensator_design.pass_through`)."""
    from ehss.target import CompensatorFilter

    n = compensator.settle_samples + compensator.preview + 1
    impulse = np.zeros(n)
    impulse[0] = 1.0
    response = CompensatorFilter(compensator).process(impulse)
    unit = np.zeros(n)
    unit[compensator.preview] = 1.0
    return bool(np.allclose(response, unit, rtol=0.0, atol=1e-12))


@dataclass(frozen=True)
class _UdpBlock:
    first_index: int
    desired: np.ndarray
    drive: np.ndarray
    feedback: np.ndarray


class UdpTarget:
    """A remote target as :class:`AdaptiveLoop` drives it.

    The target streams, in the ``ehss live`` wire format, each channel's drive
    (``ref<k>``, the model's input), feedback (``fb<k>``) and desired reference
    (``des<k>``), and takes compensators back as :mod:`ehss.target.datagram` datagrams;
    its filters read the reference ``preview`` samples ahead, and sample indices are the
    stream's.

    Parameters
    ----------
    source : UdpSource
        Receives the stream (its layout must have ``des<k>`` for every channel).
    sender : DatagramSender
    fs : float
    preview : int
    reference_rms : sequence of float
        RMS of each channel's desired reference (the estimators' scale).
    idle_stop_s : float
        The run ends when no data came for this long after the first.
    warn : callable, optional
        Called once per channel with one line when the target runs none of the
        compensators sent to it (:attr:`ignored`).

    Attributes
    ----------
    ignored : dict
        Channel index → why the target is taken not to run its compensators: its
        drive stayed exactly its desired reference (the compensator a target starts
        with, drive = reference) from the first one's apply index until
        :data:`IGNORED_AFTER_S` after the second one sent should have been faded in
        (:data:`IGNORED_LONE_S` after the first when no second was sent). A target
        refuses every compensator whose preview or sample rate is not its own, and says
        so only in its own counters.
    """

    def __init__(self, source: Any, sender: DatagramSender, *, fs: float, preview: int,
                 reference_rms: Any, idle_stop_s: float = 1.0,
                 warn: Callable[[str], None] | None = None) -> None:
        layout = source.layout
        self.channels = tuple(layout.channels)
        missing = [f"des{c}" for c in self.channels if f"des{c}" not in layout.fields]
        if missing:
            raise ParameterError(f"the stream has no field {missing[0]!r}: a target that "
                                 "takes compensators sends each channel's desired reference")
        self.source, self.sender = source, sender
        self.fs, self.preview = float(fs), int(preview)
        self.reference_rms = np.asarray(reference_rms, dtype=float)
        self._ri, self._fi = layout.ref_index, layout.fb_index
        self._di = [layout.fields.index(f"des{c}") for c in self.channels]
        self._idle = float(idle_stop_s)
        self._last: float | None = None
        self._done = False
        self.index = 0
        # (end index, arrival time) of the first and the latest block: the target's clock
        self._first_arrival: tuple[int, float] | None = None
        self._latest_arrival: tuple[int, float] | None = None
        self._largest_block = 0
        self._warn = warn
        # channel index -> (apply index, end of the fade-in) of the first two
        # compensators sent to it, while its drive is still watched
        self._expected: dict[int, list[tuple[int, int]]] = {}
        self._checked: set[int] = set()
        self.ignored: dict[int, str] = {}

    @property
    def finished(self) -> bool:
        return self._done or self.source.finished

    def load(self, channel: int, compensator: Any, apply_index: int, crossfade: int) -> bool:
        if channel not in self._checked:
            if _passes_reference(compensator):
                # compensation switched off: drive = reference is what it should run
                self._expected.pop(channel, None)
                self._checked.add(channel)
            else:
                sent = self._expected.setdefault(channel, [])
                if len(sent) < 2:
                    sent.append((int(apply_index), int(apply_index) + max(1, int(crossfade))))
        return self.sender.send(channel, compensator, apply_index, crossfade)

    def _check_applied(self, first: int, desired: np.ndarray, drive: np.ndarray) -> None:
        """Whether each watched channel's drive, on the samples of this block from its
        first compensator's apply index, shows any compensator; told when none has
        shown by :data:`IGNORED_AFTER_S` after the second one's fade-in
        (:data:`IGNORED_LONE_S` after the first's)."""
        end = first + desired.shape[1]
        for k, sent in list(self._expected.items()):
            start = sent[0][0]
            if end <= start:
                continue
            d, u = desired[k, max(0, start - first):], drive[k, max(0, start - first):]
            scale = float(np.max(np.abs(d))) if d.size else 0.0
            if scale == 0.0:
                continue                # nothing to tell it by
            if np.max(np.abs(u - d)) > 1e-12 * scale:
                del self._expected[k]   # it runs something
                self._checked.add(k)
                continue
            lone = sent[0][1] + int(round(IGNORED_LONE_S * self.fs))
            second = sent[1][1] + int(round(IGNORED_AFTER_S * self.fs)) if len(sent) > 1 \
                else lone
            if end <= min(lone, second):
                continue
            del self._expected[k]
            self._checked.add(k)
            when = (f"{IGNORED_AFTER_S:g} s after the second compensator" if second < lone
                    else f"{IGNORED_LONE_S:g} s after the first compensator")
            why = (f"channel {self.channels[k]}: the target's drive is still its desired "
                   f"reference {when} should have been faded in: it refuses them (its "
                   f"filter must read "
                   f"{self.preview} samples ahead at {self.fs:g} Hz; see its counters)")
            self.ignored[k] = why
            if self._warn is not None:
                self._warn(why)

    def _arrived(self, first: int, n: int, arrival: float) -> None:
        self._latest_arrival = (first + n, arrival)
        if self._first_arrival is None:
            self._first_arrival = (first + n, arrival)
        self._largest_block = max(self._largest_block, n)

    def ahead(self) -> int:
        """Samples the target is estimated to be past :attr:`index` now.

        The target sent the latest block that arrived when it had computed it, and has
        gone on at its own rate since: the samples that arrived but are not yet taken,
        those it has computed since that block's arrival (the rate measured from the
        arrival times of the stream so far, ``fs`` until a second has come), and one
        more block, the most it can be ahead of what it has sent."""
        if self._latest_arrival is None or self._first_arrival is None:
            return 0
        (end0, t0), (end, t) = self._first_arrival, self._latest_arrival
        rate = (end - end0) / (t - t0) if t - t0 >= 1.0 else self.fs
        since = max(0.0, time.time() - t) * rate
        return max(0, end - self.index) + int(math.ceil(since)) + self._largest_block

    def step(self, n: int) -> _UdpBlock:
        """The samples that arrived (at least one unless the stream went idle)."""
        got: list[np.ndarray] = []
        have = 0
        while have < n:
            blocks = self.source.poll(0.05)
            for b in blocks:
                got.append(b.samples)
                have += b.samples.shape[0]
                self._arrived(b.first_index, b.samples.shape[0], b.arrival_s)
            now = time.monotonic()
            if blocks:
                self._last = now
            elif self._last is not None and now - self._last >= self._idle:
                self._done = True
                break
            elif have:
                break
        x = np.concatenate(got) if got else np.empty((0, len(self.source.layout.fields)))
        first = self.index
        self.index += x.shape[0]
        block = _UdpBlock(first, x[:, self._di].T.copy(), x[:, list(self._ri)].T.copy(),
                          x[:, list(self._fi)].T.copy())
        if self._expected:
            self._check_applied(first, block.desired, block.drive)
        return block
