"""UDP transport: :class:`UdpSource` receives the datagrams of a real-time target,
:func:`stream_record` sends a record in that format (``ehss stream``).

The receiving side never trusts the network: datagrams from senders that are not
allowed are dropped before they are parsed, anything that is not a whole datagram of
the layout is counted and dropped, packets that come out of order are put back in
place within a small window, and a gap that the window cannot close is counted with the
number of samples lost. Nothing that arrives on the socket can raise.
"""

from __future__ import annotations

import ipaddress
import math
import select
import socket
import struct
import sys
import time
from collections.abc import Iterable

import numpy as np

from ehss.errors import DataError, ParameterError
from ehss.live.layout import MAX_DATAGRAM_BYTES, RecordLayout
from ehss.live.source import Block, new_counters

__all__ = ["parse_address", "UdpSource", "stream_record"]

# Linux socket options not named by the socket module
_SO_RCVBUFFORCE = 33
_SO_SNDBUFFORCE = 32
_SO_TIMESTAMPNS = 35
_TIMESPEC = struct.Struct("@qq")
#: receive buffer asked for: ~1 s of a 40 kS/s, 17-field stream
_RCVBUF_BYTES = 8 * 1024 * 1024


def parse_address(text: str, *, destination: bool = False) -> tuple[str, int]:
    """``"HOST:PORT"`` → ``(host, port)``; the host must be an IP address.

    Parameters
    ----------
    text : str
    destination : bool
        The address is one to send to, not to listen on: the port must then be named
        (1..65535) and the host must be one machine or a multicast group, not the
        unspecified address 0.0.0.0 nor the broadcast address 255.255.255.255.

    Raises
    ------
    ParameterError
        If it is not ``IPv4:PORT`` with 0 <= PORT <= 65535, or not a destination where
        one is asked for.
    """
    if not isinstance(text, str):
        raise TypeError(f"address must be a str, got {type(text).__name__}")
    host, sep, port = text.rpartition(":")
    try:
        ip = ipaddress.IPv4Address(host)
        number = int(port)
    except ValueError:
        raise ParameterError(
            f"address {text!r} must be IPv4:PORT, e.g. 127.0.0.1:5005"
        ) from None
    if not sep or not 0 <= number <= 65535:
        raise ParameterError(f"address {text!r} must be IPv4:PORT with PORT in 0..65535")
    if destination and number == 0:
        raise ParameterError(f"address {text!r}: port 0 cannot be sent to; name the "
                             "target's port (1..65535)")
    if destination and (ip.is_unspecified or ip == ipaddress.IPv4Address("255.255.255.255")):
        raise ParameterError(f"address {text!r} is not one machine: send to the target's "
                             "own address (or a multicast group)")
    return str(ip), number


#: A datagram whose first index is further than this from the expected one (2**24
#: samples: 56 min at 5 kHz) is taken as corrupted unless the next one continues it.
FAR_SAMPLES = 2**24


def _force_buffer(sock: socket.socket, opt: int, force: int, size: int) -> None:
    try:
        sock.setsockopt(socket.SOL_SOCKET, force, size)  # root: beyond rmem_max
    except OSError:
        sock.setsockopt(socket.SOL_SOCKET, opt, size)


class UdpSource:
    """Datagrams of a :class:`RecordLayout` received on a UDP socket.

    Parameters
    ----------
    layout : RecordLayout
    address : (host, port)
        Where to listen; port 0 picks a free port (see :attr:`address`).
    fs : float, optional
        Sample rate, Hz (otherwise the caller takes it from the ``t`` field).
    allow : iterable of str, optional
        Sender IP addresses accepted (default: any). The first accepted datagram also
        locks the source to its sender's (address, port): datagrams from anyone else are
        counted as ``foreign`` and dropped, so a second sender cannot interleave.
    reorder_packets : int
        Packets held while waiting for a missing one before the gap is given up on.
    reorder_s : float
        Longest time a packet is held waiting for a missing one.
    """

    def __init__(
        self, layout: RecordLayout, address: tuple[str, int], *, fs: float | None = None,
        allow: Iterable[str] | None = None, reorder_packets: int = 64,
        reorder_s: float = 0.02,
    ) -> None:
        self.layout = layout
        self.fs = fs
        self.counters = new_counters()
        self._allow = None if allow is None else {str(ipaddress.IPv4Address(a)) for a in allow}
        if reorder_packets < 1 or not (reorder_s > 0 and math.isfinite(reorder_s)):
            raise ParameterError("reorder_packets must be >= 1 and reorder_s > 0")
        self._window = int(reorder_packets)
        self._hold_s = float(reorder_s)
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            _force_buffer(self._sock, socket.SO_RCVBUF, _SO_RCVBUFFORCE, _RCVBUF_BYTES)
            self._stamps = False
            if sys.platform.startswith("linux"):
                try:
                    self._sock.setsockopt(socket.SOL_SOCKET, _SO_TIMESTAMPNS, 1)
                    self._stamps = True
                except OSError:
                    pass
            self._sock.bind(address)
        except OSError as exc:
            self._sock.close()
            raise ParameterError(f"cannot listen on {address[0]}:{address[1]}: "
                                 f"{exc.strerror or exc}") from None
        self._sock.setblocking(False)
        self._buf = bytearray(MAX_DATAGRAM_BYTES + 1)
        self._sender: tuple[str, int] | None = None
        self._expected: int | None = None
        self._pending: dict[int, tuple[np.ndarray, float, float]] = {}
        self._resync: int | None = None  # where a datagram far off the count said to go on
        self._closed = False

    @property
    def address(self) -> tuple[str, int]:
        """The (host, port) the socket is bound to."""
        return self._sock.getsockname()

    @property
    def sender(self) -> tuple[str, int] | None:
        """The sender the source locked onto, once one was accepted."""
        return self._sender

    @property
    def finished(self) -> bool:
        return self._closed

    @property
    def rcvbuf_bytes(self) -> int:
        """Receive buffer the system granted."""
        return self._sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            self._sock.close()

    # ------------------------------------------------------------------ receive
    def _recv(self) -> tuple[int, int, tuple[str, int], float] | None:
        """One datagram into the buffer: (size, flags, sender, arrival) or None."""
        try:
            if self._stamps:
                size, anc, flags, sender = self._sock.recvmsg_into(
                    [self._buf], socket.CMSG_SPACE(_TIMESPEC.size))
                arrival = None
                for level, kind, data in anc:
                    if level == socket.SOL_SOCKET and kind == _SO_TIMESTAMPNS \
                            and len(data) >= _TIMESPEC.size:
                        sec, ns = _TIMESPEC.unpack_from(data)
                        arrival = sec + ns * 1e-9
                if arrival is None:
                    arrival = time.time()
            else:
                size, sender = self._sock.recvfrom_into(self._buf)
                flags, arrival = 0, time.time()
        except (BlockingIOError, InterruptedError):
            return None
        except OSError:
            # e.g. ICMP errors reported on the socket: nothing to read
            return None
        return size, flags, sender, arrival

    def poll(self, timeout_s: float) -> list[Block]:
        """Blocks in sample order; waits at most ``timeout_s`` for the first datagram."""
        if self._closed:
            return []
        out: list[Block] = []
        try:
            ready, _, _ = select.select([self._sock], [], [], max(timeout_s, 0.0))
        except (OSError, ValueError):
            return out
        if ready:
            # drain what is there, bounded so that a flood cannot hold the caller
            for _ in range(4096):
                got = self._recv()
                if got is None:
                    break
                self._accept(*got, out)
        self._expire(out)
        return out

    def _accept(self, size: int, flags: int, sender: tuple[str, int], arrival: float,
                out: list[Block]) -> None:
        c = self.counters
        if self._sender is not None:
            if sender != self._sender:
                c["foreign"] += 1
                return
        elif self._allow is not None and sender[0] not in self._allow:
            c["foreign"] += 1
            return
        if flags & socket.MSG_TRUNC or size > MAX_DATAGRAM_BYTES:
            c["truncated"] += 1
            return
        decoded = self.layout.decode(bytes(self._buf[:size]))
        if decoded is None:
            c["malformed"] += 1
            return
        if self._sender is None:
            self._sender = sender
        first, samples = decoded
        c["packets"] += 1
        self._place(first, samples, arrival, out)

    # ------------------------------------------------------------------ ordering
    def _deliver(self, first: int, samples: np.ndarray, arrival: float,
                 out: list[Block]) -> None:
        out.append(Block(first, samples, arrival))
        self.counters["samples"] += samples.shape[0]
        self._expected = first + samples.shape[0]

    def _flush(self, out: list[Block], *, reordered: bool = True) -> None:
        """Deliver the held packets that now follow on; ``reordered``: count them as
        packets that came out of order (not so when they were held over a gap)."""
        while self._expected in self._pending:
            samples, arrival, _ = self._pending.pop(self._expected)
            self.counters["reordered"] += reordered
            self._deliver(self._expected, samples, arrival, out)

    def _far(self, first: int) -> bool:
        """Whether a datagram's index is too far from the count, either way, to be a
        gap or a reordering (:data:`FAR_SAMPLES`)."""
        return self._expected is not None and \
            not -FAR_SAMPLES <= first - self._expected <= FAR_SAMPLES

    def _place(self, first: int, samples: np.ndarray, arrival: float,
               out: list[Block]) -> None:
        if self._expected is None:
            self._expected = first
        elif self._far(first):
            # One datagram that says it is hours ahead (or behind) is a corrupted index,
            # not a gap: believing it would make every later sample "late". Two in a row
            # that continue one another are a sender that restarted its count.
            if first != self._resync:
                self._resync = first + samples.shape[0]
                self.counters["malformed"] += 1
                return
            self.counters["gaps"] += 1
            self._pending.clear()
            self._expected = first
        self._resync = None
        if first < self._expected or first in self._pending:
            self.counters["late"] += 1           # its place has passed, or a repeat
            return
        if first == self._expected:
            self._deliver(first, samples, arrival, out)
            self._flush(out)
            return
        self._pending[first] = (samples, arrival, time.monotonic())
        if len(self._pending) > self._window:
            self._give_up(out)

    def _give_up(self, out: list[Block]) -> None:
        """Declare the gap before the oldest held packet lost, and go on from there."""
        nxt = min(self._pending)
        assert self._expected is not None          # set by the first datagram
        self.counters["gaps"] += 1
        self.counters["lost_samples"] += nxt - self._expected
        self._expected = nxt
        self._flush(out, reordered=False)

    def _expire(self, out: list[Block]) -> None:
        """Give up on gaps whose oldest held packet waited longer than ``reorder_s``."""
        now = time.monotonic()
        while self._pending and now - min(v[2] for v in self._pending.values()) > self._hold_s:
            self._give_up(out)


def stream_record(
    layout: RecordLayout, samples: np.ndarray, fs: float, address: tuple[str, int], *,
    speed: float = 1.0, samples_per_packet: int = 1, first_index: int = 0,
) -> dict[str, float]:
    """Send a record to ``address`` as datagrams, paced to the wall clock.

    Parameters
    ----------
    layout : RecordLayout
    samples : ndarray, shape (n, n_fields)
    fs : float
        Sample rate of the record, Hz.
    address : (host, port)
    speed : float
        × real time (``math.inf``: as fast as the socket takes them).
    samples_per_packet : int
        Samples per datagram.
    first_index : int
        Sample index of the first sample.

    Returns
    -------
    dict
        ``packets``, ``samples``, ``wall_s`` and the largest lateness of a packet
        against its schedule, ``max_late_s``.
    """
    samples = np.ascontiguousarray(samples, dtype=np.float64)
    n = samples.shape[0]
    spp = int(samples_per_packet)
    if not 1 <= spp <= layout.max_samples_per_datagram:
        raise ParameterError(f"samples_per_packet={samples_per_packet!r} must be in 1.."
                             f"{layout.max_samples_per_datagram}")
    if not speed > 0:
        raise ParameterError(f"speed={speed!r} must be > 0")
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        _force_buffer(sock, socket.SO_SNDBUF, _SO_SNDBUFFORCE, 4 * 1024 * 1024)
    except OSError:
        pass
    period = spp / (fs * speed) if math.isfinite(speed) else 0.0
    packets, late = 0, 0.0
    t0 = time.perf_counter()
    try:
        for k, start in enumerate(range(0, n, spp)):
            due = t0 + k * period
            now = time.perf_counter()
            if due > now:
                time.sleep(due - now)
            else:
                late = max(late, now - due)
            data = layout.encode(first_index + start, samples[start:start + spp])
            while True:
                try:
                    sock.sendto(data, address)
                    break
                except (BlockingIOError, InterruptedError):
                    time.sleep(0.0005)
                except OSError as exc:
                    raise DataError(f"cannot send to {address[0]}:{address[1]}: "
                                    f"{exc.strerror or exc}") from None
            packets += 1
    finally:
        sock.close()
    return {"packets": packets, "samples": n, "wall_s": time.perf_counter() - t0,
            "max_late_s": late}
