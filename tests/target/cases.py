"""Datagrams of the documented layout, packed here from the format table (not by the
encoder), good and corrupted in every way the decoders must refuse."""

from __future__ import annotations

import struct
import zlib

import numpy as np

from ehss.target import MAX_PREVIEW, MAX_TAPS

# the table in ehss.target.datagram, written out again
_HEAD = "<4sHHQdQIII"


def frame(*, sos=((1.0, 0.5, 0.0, 1.0, -0.5, 0.25),), taps=(1.0, 0.5), channel=1,
          sequence=1, fs_hz=5000.0, apply_index=100, crossfade=50, preview=0,
          magic=b"EHSC", version=1, n_sections=None, n_taps=None, crc=None,
          extra=b"") -> bytes:
    """A datagram; every field may be given a wrong value."""
    sos = np.asarray(sos, dtype="<f8").reshape(-1, 6)
    taps = np.asarray(taps, dtype="<f8")
    ns = sos.shape[0] if n_sections is None else n_sections
    nt = taps.size if n_taps is None else n_taps
    body = (struct.pack(_HEAD, magic, version, channel, sequence, fs_hz, apply_index,
                        crossfade, preview, ns)
            + sos.tobytes() + struct.pack("<I", nt) + taps.tobytes())
    return body + struct.pack("<I", zlib.crc32(body) if crc is None else crc) + extra


def corrupted() -> list[tuple[str, bytes, str]]:
    """``(what, datagram, fault)`` for every way a datagram can be refused."""
    good = frame()
    flipped = bytearray(good)
    flipped[50] ^= 0x10
    nan, inf = float("nan"), float("inf")
    out = [
        ("empty", b"", "truncated"),
        ("header cut", good[:30], "truncated"),
        ("tap count cut", good[:44 + 48 + 2], "truncated"),
        ("taps cut", good[:-5], "truncated"),
        ("checksum cut", good[:-1], "truncated"),
        ("a byte too many", good + b"\0", "length"),
        ("sections not sent", frame(n_sections=2), "truncated"),
        ("magic", frame(magic=b"EHSS"), "magic"),
        ("version", frame(version=2), "version"),
        ("17 sections", frame(n_sections=17), "sections"),
        ("2**32 - 1 sections", frame(n_sections=2**32 - 1), "sections"),
        ("no taps", frame(taps=()), "taps"),
        (f"{MAX_TAPS + 1} taps", frame(taps=np.ones(MAX_TAPS + 1)), "taps"),
        ("tap count too large", frame(n_taps=2**31), "taps"),
        ("a bit flipped", bytes(flipped), "checksum"),
        ("wrong checksum", frame(crc=12345), "checksum"),
        ("sample rate NaN", frame(fs_hz=nan), "sample_rate"),
        ("sample rate inf", frame(fs_hz=inf), "sample_rate"),
        ("sample rate 0", frame(fs_hz=0.0), "sample_rate"),
        ("sample rate negative", frame(fs_hz=-5000.0), "sample_rate"),
        ("sample rate 2 GHz", frame(fs_hz=2e9), "sample_rate"),
        (f"preview {MAX_PREVIEW + 1}", frame(preview=MAX_PREVIEW + 1), "preview"),
        ("NaN in a section", frame(sos=[[1.0, nan, 0, 1, 0, 0]]), "non_finite"),
        ("inf in the taps", frame(taps=[1.0, -inf]), "non_finite"),
        ("NaN as a0", frame(sos=[[1.0, 0, 0, nan, 0, 0]]), "non_finite"),
        ("a0 = 0.5", frame(sos=[[1.0, 0, 0, 0.5, 0, 0]]), "not_normalised"),
        ("poles on the circle", frame(sos=[[1.0, 0, 0, 1, 0, 1.0]]), "unstable"),
        ("pole at z = 1", frame(sos=[[1.0, 0, 0, 1, -1.0, 0]]), "unstable"),
        ("pole at z = 1.05", frame(sos=[[1.0, 0, 0, 1, -1.05, 0]]), "unstable"),
        ("poles at 1.01 e^{±j}", frame(sos=[[1.0, 0, 0, 1, -2 * 1.01 * np.cos(1.0),
                                             1.01**2]]), "unstable"),
        ("second section unstable", frame(sos=[[1.0, 0, 0, 1, 0.5, 0.0],
                                               [1.0, 0, 0, 1, 0.0, -1.2]]), "unstable"),
    ]
    return out
