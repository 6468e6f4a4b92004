"""``ehss stream``: send the simulated rig or a recorded file to a UDP address, in the
datagram format ``ehss live --udp`` reads."""

from __future__ import annotations

import argparse
import math
import sys

from ehss.cli._live import add_command, add_rig_arguments, rig_or_replay
from ehss.cli._outputs import InputFile
from ehss.errors import ParameterError

__all__ = ["register", "run"]


def register(sub: argparse._SubParsersAction) -> None:
    p = add_command(
        sub, "stream",
        "Play the simulated rig (computed up front, then paced to the wall clock) or a "
        "recorded file\nto a UDP address, as a real-time target would.",
        "ehss stream --rig position --channels 8 --fs 5000 --duration 10 --to "
        "127.0.0.1:5005 --samples-per-packet 5")
    p.add_argument("--to", required=True, metavar="HOST:PORT", help="destination")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--rig", choices=("position", "acceleration", "force"),
                     help="the simulated rig (fields t, ref1, fb1, ...)")
    src.add_argument("--replay", metavar="FILE", type=InputFile, help="a recording or data file")
    p.add_argument("--fields", metavar="t,ref1,fb1,...",
                   help="--replay: columns to send, each as a field or as FIELD=COLUMN "
                   "(t=time_s,ref1=cmd,fb1=pos)")
    p.add_argument("--fs", type=float, metavar="HZ",
                   help="sample rate (default: the parameter set's or the file's)")
    p.add_argument("--samples-per-packet", type=int, default=None, metavar="N",
                   help="samples per datagram (default: 1 ms of samples)")
    add_rig_arguments(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ehss.live.udp import parse_address, stream_record

    address = parse_address(args.to, destination=True)
    layout, samples, fs = rig_or_replay(args, "stream")
    spp = (max(1, round(fs / 1000.0)) if args.samples_per_packet is None
           else args.samples_per_packet)
    if not 1 <= spp <= layout.max_samples_per_datagram:
        raise ParameterError(f"--samples-per-packet {spp}: a datagram holds 1 to "
                             f"{layout.max_samples_per_datagram} samples of "
                             f"{layout.n_fields} fields (at most 65507 bytes)")
    print(f"ehss stream: {samples.shape[0]} samples of {layout.n_fields} fields "
          f"({','.join(layout.fields)}) at {fs:g} Hz to {address[0]}:{address[1]}, "
          f"{spp} per datagram", file=sys.stderr, flush=True)
    done = stream_record(layout, samples, fs, address, speed=args.speed,
                         samples_per_packet=spp)
    late = done["max_late_s"]
    print(f"ehss stream: sent {done['packets']} datagrams in {done['wall_s']:.2f} s"
          + ("" if math.isinf(args.speed) else f" (largest lateness {late * 1e3:.1f} ms)"),
          file=sys.stderr)
    return 0
