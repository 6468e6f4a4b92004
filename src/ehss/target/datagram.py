"""The UDP datagram that carries one channel's compensator from the host to the target.

All fields little-endian; ``S`` sections and ``T`` taps:

============  ========  ===================================================================
offset        type      meaning
============  ========  ===================================================================
0             4 bytes   magic ``b"EHSC"``
4             uint16    format version, 1
6             uint16    channel, 0..65535 (the target's own numbering of its loops)
8             uint64    sequence number: a datagram not newer than the last one loaded
                        for its channel is ignored
16            float64   sample rate of the model the compensator was designed from, Hz
24            uint64    apply index: the sample from which the compensator applies
32            uint32    cross-fade length N, samples (0 or 1: switch outright)
36            uint32    preview p, samples (0: causal), at most MAX_PREVIEW = 2047
40            uint32    number of second-order sections S, 0..16
44            float64   6·S section coefficients, row by row: ``b0 b1 b2 a0 a1 a2``
44 + 48 S     uint32    number of FIR taps T, 1..2048
48 + 48 S     float64   T taps ``h_0 … h_{T-1}``
48 + 48 S     uint32    CRC-32 (``zlib.crc32``, the IEEE 802.3 polynomial) of every byte
+ 8 T                   before it
============  ========  ===================================================================

so a datagram is ``52 + 48 S + 8 T`` bytes (at most 17 204: a target's UDP stack must
take IP fragments, as loopback and the usual stacks do; 2 868 bytes at the 256 taps of
1 kHz). A datagram is refused, and counted by the first of these faults it has (the C
decoder checks the same, in the same order): ``truncated`` (shorter than its counts
say), ``magic``, ``version``, ``sections`` (S > 16), ``taps`` (T = 0 or T > 2048),
``length`` (longer than its counts say), ``checksum``, ``sample_rate`` (not finite or
outside 1e-9..1e9 Hz), ``preview`` (p > 2047), ``non_finite`` (a NaN or infinite
coefficient), ``not_normalised`` (a section's ``a0`` is not 1) and ``unstable`` (a
section with a pole on or outside the unit circle).

The sequence number orders the updates of one channel: a host numbers them upwards
(e.g. from the Unix time in milliseconds when it starts, so that a restarted host keeps
numbering upwards) and the target ignores a datagram whose number is not above the last
one it loaded for that channel (a late or repeated datagram, counted ``stale``); see
:class:`Inbox` for the other reasons a whole datagram is not loaded.
"""

from __future__ import annotations

import math
import struct
import zlib
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from ehss._checks import SAMPLE_RATE_RANGE_HZ, check_int
from ehss.target.filter import (
    MAX_PREVIEW,
    MAX_SECTIONS,
    MAX_TAPS,
    Compensator,
    CompensatorFilter,
    coefficient_fault,
)

__all__ = [
    "MAGIC",
    "VERSION",
    "HEADER",
    "COUNT",
    "CHECKSUM",
    "FAULTS",
    "MAX_DATAGRAM_BYTES",
    "CompensatorUpdate",
    "datagram_bytes",
    "encode",
    "decode",
    "RESULTS",
    "Inbox",
]

MAGIC = b"EHSC"
VERSION = 1
#: magic, version, channel, sequence, fs_hz, apply index, cross-fade, preview, S
HEADER = struct.Struct("<4sHHQdQIII")
#: the tap count T after the sections
COUNT = struct.Struct("<I")
#: the CRC-32 at the end
CHECKSUM = struct.Struct("<I")

#: Faults a datagram can have, in the order they are checked; the C decoder returns
#: ``EHSS_COMP_FAULT_<KIND>`` = 1 + the index here.
FAULTS = ("truncated", "magic", "version", "sections", "taps", "length", "checksum",
          "sample_rate", "preview", "non_finite", "not_normalised", "unstable")


#: Results of receiving a datagram, in the order of the C code's ``ehss_comp_result``
#: (``EHSS_COMP_OK`` = 0 … ``EHSS_COMP_OTHER_SAMPLE_RATE`` = 17).
RESULTS = ("ok", *FAULTS, "stale", "other_channel", "other_preview", "busy",
           "other_sample_rate")


def datagram_bytes(n_sections: int, n_taps: int) -> int:
    """Size of a datagram of ``n_sections`` sections and ``n_taps`` taps, bytes."""
    return HEADER.size + 48 * n_sections + COUNT.size + 8 * n_taps + CHECKSUM.size


#: Largest datagram: 16 sections and 2048 taps.
MAX_DATAGRAM_BYTES = datagram_bytes(MAX_SECTIONS, MAX_TAPS)


@dataclass(frozen=True)
class CompensatorUpdate:
    """One channel's compensator and when to apply it: what a datagram carries.

    Parameters
    ----------
    channel : int
        0..65535.
    sequence : int
        0..2**64 - 1, rising from one update of the channel to the next.
    apply_index : int
        Sample index from which the compensator applies (0..2**64 - 1).
    crossfade : int
        Cross-fade length, samples (0..2**32 - 1).
    compensator : Compensator
    """

    channel: int
    sequence: int
    apply_index: int
    crossfade: int
    compensator: Compensator

    def __post_init__(self) -> None:
        object.__setattr__(self, "channel", check_int(self.channel, "channel", lo=0,
                                                      hi=2**16 - 1))
        object.__setattr__(self, "sequence", check_int(self.sequence, "sequence", lo=0,
                                                       hi=2**64 - 1))
        object.__setattr__(self, "apply_index", check_int(self.apply_index, "apply_index",
                                                          lo=0, hi=2**64 - 1))
        object.__setattr__(self, "crossfade", check_int(self.crossfade, "crossfade", lo=0,
                                                        hi=2**32 - 1))
        if not isinstance(self.compensator, Compensator):
            raise TypeError(f"compensator must be a Compensator, not "
                            f"{type(self.compensator).__name__}")


def encode(update: CompensatorUpdate) -> bytes:
    """The datagram carrying ``update`` (see the module notes for the format)."""
    if not isinstance(update, CompensatorUpdate):
        raise TypeError(f"update must be a CompensatorUpdate, not {type(update).__name__}")
    c = update.compensator
    body = b"".join((
        HEADER.pack(MAGIC, VERSION, update.channel, update.sequence, c.fs_hz,
                    update.apply_index, update.crossfade, c.preview, c.n_sections),
        np.ascontiguousarray(c.sos, dtype="<f8").tobytes(),
        COUNT.pack(c.n_taps),
        np.ascontiguousarray(c.taps, dtype="<f8").tobytes(),
    ))
    return body + CHECKSUM.pack(zlib.crc32(body))


def _frame_fault(data: bytes) -> str | None:
    """Faults of the frame: its length, magic, version, counts and checksum."""
    size = len(data)
    if size < HEADER.size:
        return "truncated"
    magic, version, *_, n_sections = HEADER.unpack_from(data)
    if magic != MAGIC:
        return "magic"
    if version != VERSION:
        return "version"
    if n_sections > MAX_SECTIONS:
        return "sections"
    at_taps = HEADER.size + 48 * n_sections
    if size < at_taps + COUNT.size:
        return "truncated"
    (n_taps,) = COUNT.unpack_from(data, at_taps)
    if not 1 <= n_taps <= MAX_TAPS:
        return "taps"
    total = datagram_bytes(n_sections, n_taps)
    if size < total:
        return "truncated"
    if size > total:
        return "length"
    (crc,) = CHECKSUM.unpack_from(data, total - CHECKSUM.size)
    if crc != zlib.crc32(data[: total - CHECKSUM.size]):
        return "checksum"
    return None


def decode(data: bytes) -> CompensatorUpdate | str:
    """The update a datagram carries, or the kind of its first fault (one of
    :data:`FAULTS`). Never raises on any bytes.

    Parameters
    ----------
    data : bytes, bytearray or memoryview

    Raises
    ------
    TypeError
        If ``data`` is not bytes-like (an int would otherwise be read as that many
        zero bytes).
    """
    if not isinstance(data, (bytes, bytearray, memoryview)):
        raise TypeError(f"data must be bytes, not {type(data).__name__}")
    data = bytes(data)
    fault = _frame_fault(data)
    if fault is not None:
        return fault
    _, _, channel, sequence, fs_hz, apply_index, crossfade, preview, n_sections = \
        HEADER.unpack_from(data)
    lo, hi = SAMPLE_RATE_RANGE_HZ
    if not (math.isfinite(fs_hz) and lo <= fs_hz <= hi):
        return "sample_rate"
    if preview > MAX_PREVIEW:
        return "preview"
    at_taps = HEADER.size + 48 * n_sections
    (n_taps,) = COUNT.unpack_from(data, at_taps)
    sos = np.frombuffer(data, dtype="<f8", count=6 * n_sections, offset=HEADER.size)
    taps = np.frombuffer(data, dtype="<f8", count=n_taps, offset=at_taps + COUNT.size)
    sos = sos.astype(np.float64).reshape(n_sections, 6)
    taps = taps.astype(np.float64)
    fault = coefficient_fault(sos, taps)
    if fault is not None:
        return fault
    compensator = Compensator(sos=sos, taps=taps, preview=preview, fs_hz=fs_hz)
    return CompensatorUpdate(channel=channel, sequence=sequence, apply_index=apply_index,
                             crossfade=crossfade, compensator=compensator)


class Inbox:
    """The target's receiving end: datagrams in, each update loaded into its channel's
    filter — what ``ehss_comp_decode`` does in the C code, with the same results.

    Parameters
    ----------
    filters : mapping of int to CompensatorFilter
        The filter of each channel the target runs.

    Attributes
    ----------
    counters : dict of str to int
        How many datagrams had each result of :data:`RESULTS`.

    Notes
    -----
    A datagram is checked in this order, and counted by its first result: the faults
    of :data:`FAULTS`; ``other_channel`` (no filter for its channel); ``other_preview``
    (its preview differs from the channel's filter's); ``other_sample_rate`` (its
    sample rate is more than 0.1 % from the filter's); ``stale`` (its sequence number
    is not above the last one loaded for its channel); ``busy`` (an update still waits
    for a cross-fade to end; the host sends it again later); ``ok`` (loaded: the filter
    takes it up at its next sample boundary outside a cross-fade).
    """

    def __init__(self, filters: Mapping[int, CompensatorFilter]) -> None:
        self._filters = dict(filters)
        for channel, f in self._filters.items():
            check_int(channel, "channel", lo=0, hi=2**16 - 1)
            if not isinstance(f, CompensatorFilter):
                raise TypeError(f"filters[{channel}] must be a CompensatorFilter, not "
                                f"{type(f).__name__}")
        self.counters = dict.fromkeys(RESULTS, 0)
        self._last: dict[int, int] = {}

    def last_sequence(self, channel: int) -> int | None:
        """Sequence number of the last update loaded for ``channel``, if any."""
        return self._last.get(channel)

    def _result(self, got: CompensatorUpdate | str) -> str:
        if isinstance(got, str):
            return got
        f = self._filters.get(got.channel)
        if f is None:
            return "other_channel"
        refused = f.accepts(got.compensator)
        if refused is not None:
            return refused
        last = self._last.get(got.channel)
        if last is not None and got.sequence <= last:
            return "stale"
        if f.waiting:
            return "busy"
        f.load(got.compensator, got.apply_index, got.crossfade)
        self._last[got.channel] = got.sequence
        return "ok"

    def accept(self, data: Any) -> str:
        """Decode ``data`` and load its update; returns the result (one of
        :data:`RESULTS`). Never raises on any bytes."""
        result = self._result(decode(data))
        self.counters[result] += 1
        return result
