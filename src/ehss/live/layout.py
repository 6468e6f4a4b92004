"""The record layout of a live stream: named float64 fields, and its UDP datagram form.

A datagram is a 16-byte little-endian header followed by one or more samples:

==========  =======  =====================================================================
offset      type     meaning
==========  =======  =====================================================================
0           4 bytes  magic ``b"EHSS"``
4           uint16   format version, 1
6           uint16   number of fields per sample, F (must equal the ``--fields`` count)
8           uint64   index of the packet's first sample, counted from 0 at stream start
16          float64  F·n values: sample 0's fields in ``--fields`` order, then sample 1 …
==========  =======  =====================================================================

so a datagram of ``16 + 8·F·n`` bytes carries n ≥ 1 samples (at most 65 507 bytes: n ≤
⌊65 491 / (8F)⌋). Sample indices of consecutive packets follow each other; a jump
forward is a gap, a step back is a late (reordered) or repeated packet.

Channels are formed from the field names: ``ref<k>`` (the loop's reference, the model's
input u) and ``fb<k>`` (the measured feedback, the model's output y) with the same
suffix ``<k>`` make channel ``<k>``. A field ``t`` (s) is the target's clock; any other
field is recorded but not processed.
"""

from __future__ import annotations

import re
import struct
from dataclasses import dataclass, field

import numpy as np

from ehss.errors import ParameterError

__all__ = [
    "MAGIC",
    "VERSION",
    "HEADER",
    "HEADER_BYTES",
    "MAX_DATAGRAM_BYTES",
    "RecordLayout",
    "parse_fields",
]

MAGIC = b"EHSS"
VERSION = 1
#: struct of the header: magic, version, field count, first sample index
HEADER = struct.Struct("<4sHHQ")
HEADER_BYTES = HEADER.size
#: largest UDP payload over IPv4
MAX_DATAGRAM_BYTES = 65_507

_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


def parse_fields(text: str) -> tuple[str, ...]:
    """Field names from ``"t,ref1,fb1,..."``.

    Raises
    ------
    ParameterError
        Empty, repeated or non-identifier names, or no ``ref<k>``/``fb<k>`` pair.
    """
    if not isinstance(text, str):
        raise TypeError(f"fields must be a str, got {type(text).__name__}")
    names = tuple(s.strip() for s in text.split(","))
    return RecordLayout(fields=names).fields


@dataclass(frozen=True)
class RecordLayout:
    """Named float64 fields of one sample, and the channels they form.

    Parameters
    ----------
    fields : tuple of str
        Field names in wire order (see the module notes).

    Attributes
    ----------
    channels : tuple of str
        Channel names (the suffixes ``<k>`` of the ``ref<k>``/``fb<k>`` pairs), in the
        order their ``ref`` fields appear.
    ref_index, fb_index : tuple of int
        Column of each channel's reference and feedback.
    time_index : int or None
        Column of ``t``, if present.
    """

    fields: tuple[str, ...]
    channels: tuple[str, ...] = field(init=False)
    ref_index: tuple[int, ...] = field(init=False)
    fb_index: tuple[int, ...] = field(init=False)
    time_index: int | None = field(init=False)

    def __post_init__(self) -> None:
        names = tuple(self.fields)
        if not names or any(not isinstance(n, str) for n in names):
            raise ParameterError(f"fields={names!r} must be a non-empty list of names")
        for n in names:
            if not _NAME.match(n):
                raise ParameterError(
                    f"field name {n!r} must be a letter or _ followed by letters, digits or _"
                )
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ParameterError(f"field names must be unique; repeated: {dup}")
        if 8 * len(names) + HEADER_BYTES > MAX_DATAGRAM_BYTES:
            raise ParameterError(f"{len(names)} fields do not fit one UDP datagram")
        chans, ri, fi = [], [], []
        for i, n in enumerate(names):
            if n.startswith("ref"):
                k = n[3:]
                if f"fb{k}" not in names:
                    raise ParameterError(f"field {n!r} has no feedback field 'fb{k}'")
                chans.append(k or "0")
                ri.append(i)
                fi.append(names.index(f"fb{k}"))
        for n in names:
            if n.startswith("fb") and f"ref{n[2:]}" not in names:
                raise ParameterError(f"field {n!r} has no reference field 'ref{n[2:]}'")
        if not chans:
            raise ParameterError(
                f"fields={','.join(names)} form no channel: name a reference 'ref<k>' and "
                "its feedback 'fb<k>' (e.g. t,ref1,fb1,ref2,fb2)"
            )
        object.__setattr__(self, "fields", names)
        object.__setattr__(self, "channels", tuple(chans))
        object.__setattr__(self, "ref_index", tuple(ri))
        object.__setattr__(self, "fb_index", tuple(fi))
        object.__setattr__(self, "time_index", names.index("t") if "t" in names else None)

    @property
    def n_fields(self) -> int:
        """Number of float64 fields per sample, F."""
        return len(self.fields)

    @property
    def sample_bytes(self) -> int:
        """Bytes of one sample on the wire, 8·F."""
        return 8 * len(self.fields)

    @property
    def max_samples_per_datagram(self) -> int:
        """Largest number of samples one datagram can carry."""
        return (MAX_DATAGRAM_BYTES - HEADER_BYTES) // self.sample_bytes

    def encode(self, first_index: int, samples: np.ndarray) -> bytes:
        """One datagram carrying ``samples`` (shape (n, F)) from sample ``first_index``."""
        samples = np.ascontiguousarray(samples, dtype="<f8")
        if samples.ndim != 2 or samples.shape[1] != self.n_fields or samples.shape[0] < 1:
            raise ParameterError(
                f"samples have shape {samples.shape}, must be (n >= 1, {self.n_fields})"
            )
        if samples.shape[0] > self.max_samples_per_datagram:
            raise ParameterError(
                f"{samples.shape[0]} samples exceed one datagram "
                f"(at most {self.max_samples_per_datagram} of {self.n_fields} fields)"
            )
        return HEADER.pack(MAGIC, VERSION, self.n_fields, int(first_index)) + samples.tobytes()

    def decode(self, data: bytes) -> tuple[int, np.ndarray] | None:
        """``(first_index, samples)`` of a datagram, or None when it is not one of ours.

        Anything that is not a whole datagram of this layout (wrong length, magic,
        version or field count, non-finite values) gives None: the caller counts it.
        """
        size = len(data)
        if size < HEADER_BYTES + self.sample_bytes:
            return None
        if (size - HEADER_BYTES) % self.sample_bytes:
            return None
        magic, version, n_fields, first = HEADER.unpack_from(data)
        if magic != MAGIC or version != VERSION or n_fields != self.n_fields:
            return None
        values = np.frombuffer(data, dtype="<f8", offset=HEADER_BYTES)
        if not np.isfinite(values).all():
            return None
        return int(first), values.reshape(-1, self.n_fields).astype(np.float64)
