"""``ehss live --compensate``: adapt each channel's inverse-model compensator while the
simulated rig runs, and report what it did."""

from __future__ import annotations

import argparse
import json
import math
import signal
import sys
import threading

import numpy as np

import ehss
from ehss._checks import check_real
from ehss._provenance import versions
from ehss.errors import ParameterError

__all__ = ["run_compensated"]

#: Samples of reference the target's filter reads ahead in preview mode: half of its
#: FIR (the other half holds the causal tail of the inverse).
PREVIEW_SAMPLES = 128


def _rig_target(args: argparse.Namespace, duration_s: float):
    from ehss.cli._params import warn_if_unstable
    from ehss.live.rig import RIG_SIGNAL, SteppingRig, parse_event, rig_reference

    params = ehss.load_params(args.params) if args.params else ehss.preset(args.preset)
    warn_if_unstable("live", params, args.rig,
                     f"--params {args.params}" if args.params else f"--preset {args.preset}")
    fs = params.timing.control_rate_hz if args.fs is None else float(args.fs)
    rms, band = RIG_SIGNAL[args.rig]
    band = band if args.band is None else tuple(args.band)
    if args.rms is not None:
        rms = check_real(args.rms, "--rms", lo=0.0, lo_open=True)
    n = int(round(duration_s * fs))
    desired = np.vstack([rig_reference(n, fs, band_hz=band, rms=rms, seed=args.seed + k)
                         for k in range(1, args.channels + 1)])
    events = tuple(parse_event(e) for e in args.event)
    preview = PREVIEW_SAMPLES if args.compensate == "preview" else 0
    target = SteppingRig(args.rig, desired, fs=fs, params=params, events=events,
                         preview=preview, seed=args.seed)
    return target, params, band


def _udp_target(args: argparse.Namespace):
    """A remote target: its stream on --udp (t, ref<k>, fb<k>, des<k>), its compensator
    port --target."""
    from ehss.live.compensate import DatagramSender, UdpTarget
    from ehss.live.layout import RecordLayout, parse_fields
    from ehss.live.udp import UdpSource, parse_address

    missing = [flag for flag, v in (("--fields", args.fields), ("--fs", args.fs),
                                    ("--band", args.band), ("--rms", args.rms),
                                    ("--target", args.target)) if v is None]
    if missing:
        raise ParameterError(f"--compensate with --udp needs {', '.join(missing)}: the "
                             "stream's fields (t,ref1,fb1,des1,...), its rate, the band "
                             "and RMS of its reference, and where the compensators go")
    fs = check_real(args.fs, "--fs", lo=0.0, lo_open=True, unit="Hz")
    rms = check_real(args.rms, "--rms", lo=0.0, lo_open=True)
    layout = RecordLayout(parse_fields(args.fields))
    sender = DatagramSender(parse_address(args.target))
    source = UdpSource(layout, parse_address(args.udp), fs=fs)
    preview = PREVIEW_SAMPLES if args.compensate == "preview" else 0
    try:
        target = UdpTarget(source, sender, fs=fs, preview=preview,
                           reference_rms=[rms] * len(layout.channels),
                           idle_stop_s=2.0 if args.idle_stop is None else args.idle_stop)
    except ParameterError:
        source.close()
        sender.close()
        raise
    return target, tuple(args.band)


def run_compensated(args: argparse.Namespace, duration_s: float) -> int:
    """The ``--compensate`` run of ``ehss live`` (``--rig`` or ``--udp``); exit status."""

    if args.rig is None and args.udp is None:
        raise ParameterError("--compensate runs with --rig (the simulated rig's filters "
                             "take the compensators) or --udp with --target (a remote "
                             "target takes them as ehss.target datagrams)")
    for flag, value in (("--record", args.record), ("--dashboard", args.dashboard),
                        ("--baseline", args.baseline or None)):
        if value is not None:
            raise ParameterError(f"{flag} does not apply with --compensate: its log, "
                                 "loads and figures go to --report")
    if args.udp is not None:
        target, band = _udp_target(args)
        params = None
        try:
            return _run(args, target, None, band)
        finally:
            target.source.close()
            target.sender.close()
    target, params, band = _rig_target(args, duration_s)
    return _run(args, target, params, band)


def _run(args: argparse.Namespace, target, params, band) -> int:
    from ehss.live.compensate import AdaptiveLoop, CompensationSettings
    from ehss.live.rig import SteppingRig

    settings = CompensationSettings(mode=args.compensate, band_hz=band)

    def log(event: dict) -> None:
        if event["kind"] in ("alarm", "clear", "compensator_refused", "compensator"):
            keep = ("kind", "channel", "t_s", "reason", "text", "accepted",
                    "max_amplitude_error_db", "max_phase_error_deg")
            print("ehss live: " + json.dumps({k: event[k] for k in keep if k in event}),
                  file=sys.stderr, flush=True)

    loop = AdaptiveLoop(target, settings, loop=args.rig if params is not None else None,
                        params=params, log=None if args.quiet else log)
    print(f"ehss live: compensating ({args.compensate}), band {band[0]:g}-{band[1]:g} Hz",
          file=sys.stderr, flush=True)
    stop = threading.Event()
    previous = signal.getsignal(signal.SIGTERM)
    main = threading.current_thread() is threading.main_thread()
    if main:
        signal.signal(signal.SIGTERM, lambda *_: stop.set())
    try:
        rec = loop.run(speed=args.speed, stop=stop, duration_s=args.stop_after)
    except KeyboardInterrupt:
        return 130
    finally:
        if main:
            signal.signal(signal.SIGTERM, previous)
    n = rec.desired.shape[1]
    if params is not None:
        # the same rig without compensation, for the comparison
        plain = SteppingRig(args.rig, target.desired[:, :n], fs=target.fs, params=params,
                            events=target.events, seed=args.seed).step(n)
        err = plain.desired[:, n // 2:] - plain.feedback[:, n // 2:]
    else:
        # a remote target: its first second, before any compensator
        m = min(n, int(target.fs))
        err = rec.desired[:, :m] - rec.feedback[:, :m]
    without = np.sqrt(np.mean(err * err, axis=1))
    with_ = rec.tracking_rms(n / 2 / rec.fs, n / rec.fs)
    channels = {}
    for k, name in enumerate(rec.channels):
        channels[name] = {
            "tracking_rms": float(with_[k]), "tracking_rms_without": float(without[k]),
            "loads": sum(1 for ld in rec.loads if ld["channel"] == name),
            "refusals": sum(1 for d in rec.decisions[name] if not d["accepted"]),
        }
        print(f"ehss live: channel {name}: tracking RMS over the second half "
              f"{with_[k]:.4g} (without compensation {without[k]:.4g}, "
              f"{without[k] / with_[k] if with_[k] > 0 else math.inf:.1f}x), "
              f"{channels[name]['loads']} compensators loaded, "
              f"{channels[name]['refusals']} refused", file=sys.stderr)
    if args.report:
        ehss.write_json(args.report, {
            "compensation": rec.settings, "channels": channels, "loads": rec.loads,
            "decisions": rec.decisions, "events": rec.events,
            "settings": {"argv": sys.argv[1:]}, "versions": versions()})
    return 0
