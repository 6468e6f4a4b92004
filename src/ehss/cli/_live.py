"""``ehss live``: identify a running rig online, detect changes, record, and show it."""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np

import ehss
from ehss._checks import check_band, check_int, check_real
from ehss._provenance import versions
from ehss.cli import command_help
from ehss.cli._outputs import InputFile, OutputFile
from ehss.errors import DataError, ParameterError

__all__ = ["register", "run", "add_command", "add_rig_arguments", "rig_or_replay",
           "WIRE_FORMAT", "Display", "baselines", "estimation_settings", "finish",
           "stop_on_sigterm"]

WIRE_FORMAT = """\
wire format (--udp): one UDP datagram = a 16-byte little-endian header, then n >= 1
samples of F float64 fields (little-endian), sample after sample, the fields of each
sample in --fields order:
  bytes 0-3   magic b"EHSS"
  bytes 4-5   uint16 version = 1
  bytes 6-7   uint16 F, the number of fields (must equal the --fields count)
  bytes 8-15  uint64 index of the packet's first sample (0 at the stream's start;
              the next packet starts at index + n)
  bytes 16-   n*F float64 values (datagram length 16 + 8*F*n bytes, at most 65507)
Channels: fields ref<k> (reference, model input) and fb<k> (feedback, model output)
with the same suffix form channel <k>; a field t (s) is the target's clock; other
fields are recorded only. Gaps, reordered, late, malformed and foreign datagrams
(senders outside --allow, or other than the first accepted sender) are counted and
dropped; the receiver never stops on bad input.
"""


def add_rig_arguments(p: argparse.ArgumentParser) -> None:
    """Options of the simulated rig and of replayed files (shared with ehss stream)."""
    p.add_argument("--channels", type=int, default=1, metavar="N",
                   help="--rig: number of actuator channels (default: %(default)s)")
    p.add_argument("--duration", type=float, metavar="S",
                   help=f"--rig: length of the run, s (default: {RIG_DURATION_S:g})")
    p.add_argument("--event", action="append", default=[], metavar="T:NAME=VALUE[@CH]",
                   help="--rig: a parameter change at T s, on channel CH or all, e.g. "
                   "30:mass_kg=350@1 (repeatable; NAME may be group.field)")
    p.add_argument("--seed", type=int, default=0,
                   help="--rig: seed of the references and sensor noise (default: 0)")
    p.add_argument("--preset", choices=("default", "paper"), default="default",
                   help="--rig: parameter set (default: %(default)s)")
    p.add_argument("--params", metavar="FILE.toml", type=InputFile, help="--rig: parameter file")
    p.add_argument("--speed", type=float, default=1.0, metavar="X",
                   help="--rig/--replay: × real time; inf for as fast as possible "
                   "(default: %(default)s)")


def _check_positive(name: str, value: float, *, allow_inf: bool = False) -> float:
    if allow_inf and value == math.inf:
        return value
    return check_real(value, name, lo=0.0, lo_open=True)


#: length of a simulated rig run without --duration, s
RIG_DURATION_S = 60.0
#: stream time before detection without --learn, s
LEARN_S = 10.0


def _rig_only(args: argparse.Namespace, command: str) -> None:
    """Refuse the options that shape the simulated rig when the data come from
    elsewhere: they would be ignored."""
    if args.event:
        raise ParameterError("--event applies to --rig only")
    if args.duration is not None:
        hint = ("; --stop-after S stops the run after S s of stream" if command == "live"
                else "; a replayed file plays to its end")
        raise ParameterError(f"--duration applies to --rig only (the length of the "
                             f"simulated run){hint}")


def rig_or_replay(args: argparse.Namespace, command: str
                  ) -> tuple[Any, np.ndarray, float]:
    """``(layout, samples, fs)`` of ``--rig LOOP`` or ``--replay FILE``; ``command``
    names the command in a warning (a simulated loop its gains leave unstable)."""
    from ehss.cli._params import warn_if_unstable
    from ehss.live.layout import parse_fields
    from ehss.live.replay import replay_record
    from ehss.live.rig import parse_event, rig_record

    _check_positive("--speed", args.speed, allow_inf=True)
    if args.fs is not None:
        _check_positive("--fs", args.fs)
    if args.rig is not None:
        events = tuple(parse_event(e) for e in args.event)
        params = ehss.load_params(args.params) if args.params else ehss.preset(args.preset)
        duration = RIG_DURATION_S if args.duration is None else args.duration
        _check_positive("--duration", duration)
        late = [text for text, e in zip(args.event, events, strict=True)
                if e.time_s >= duration]
        if late:
            raise ParameterError(f"--event {late[0]!r} comes after the end of the "
                                 f"{duration:g} s run: it would never happen")
        source = f"--params {args.params}" if args.params else f"--preset {args.preset}"
        warn_if_unstable(command, params, args.rig, source)
        return rig_record(args.rig, n_channels=args.channels, duration_s=duration,
                          fs=args.fs, params=params, events=events, seed=args.seed)
    _rig_only(args, command)
    if args.fields is not None and not args.fields.strip():
        raise ParameterError("--fields is empty: name the columns to take, or leave it out")
    if not args.fields or "=" not in args.fields:
        fields = parse_fields(args.fields) if args.fields else None
        return replay_record(args.replay, fields=fields, fs=args.fs)
    pairs = [item.partition("=") for item in args.fields.split(",")]
    bad = [f + s for f, s, c in pairs if not s or not c.strip()]
    if bad:
        raise ParameterError(f"--fields {args.fields!r}: give every field as FIELD=COLUMN "
                             f"(t=time_s,ref1=cmd,fb1=pos) or none; {bad[0]!r} is not")
    fields = parse_fields(",".join(f for f, _, _ in pairs))
    return replay_record(args.replay, fields=fields, fs=args.fs,
                         columns=tuple(c.strip() for _, _, c in pairs))


def add_command(sub: argparse._SubParsersAction, name: str, description: str,
                example: str) -> argparse.ArgumentParser:
    """A live command's parser: its description followed by the wire format."""
    return sub.add_parser(name, help=command_help(name), epilog=f"example: {example}",
                          formatter_class=argparse.RawDescriptionHelpFormatter,
                          description=f"{description}\n\n{WIRE_FORMAT}")


#: Options of ``ehss live`` by group: (flag, argparse keywords).
_OPTIONS: dict[str, tuple[tuple[str, dict[str, Any]], ...]] = {
    "source": (
        ("--fields", dict(metavar="t,ref1,fb1,...", help=(
            "--udp: the fields of one sample, in wire order (required); --replay: the "
            "columns to take, each as a field or as FIELD=COLUMN for a file with its own "
            "names (t=time_s,ref1=cmd,fb1=pos)"))),
        ("--fs", dict(type=float, metavar="HZ", help=(
            "sample rate (default: the parameter set's, the file's, or from the t field)"))),
        ("--allow", dict(metavar="IP[,IP...]",
                         help="--udp: accept datagrams from these senders only")),
    ),
    "estimation": (
        ("--na", dict(type=int, default=4, metavar="N", help="order of A (default: 4)")),
        ("--nb", dict(type=int, default=3, metavar="N", help="order of B (default: 3)")),
        ("--nc", dict(type=int, default=4, metavar="N", help="order of C (default: 4)")),
        ("--delay", dict(type=int, default=1, metavar="D", help="delay (default: 1)")),
        ("--method", dict(choices=("rels", "rml"), default="rml", help=(
            "rml (default): recursive maximum likelihood, unbiased when the feedback "
            "carries mostly sensor noise; rels: the paper's eqs (19)-(22)"))),
        ("--memory", dict(type=float, default=0.3, metavar="S", help=(
            "memory of the forgetting factor, λ = 1 - 1/(S·fs) (default: %(default)s s); "
            "with --compensate also the compensators' estimators'"))),
        ("--forgetting", dict(type=float, metavar="LAMBDA", help="λ itself")),
        ("--p0", dict(type=float, default=1e6, metavar="ALPHA", help=(
            "P(0) = α I on the scaled data; tr P(0) also bounds tr P (default: "
            "%(default)g)"))),
        ("--u-scale", dict(type=float, metavar="U", help=(
            "scale of the references (default: RMS of the first 0.5 s)"))),
        ("--y-scale", dict(type=float, metavar="Y", help=(
            "scale of the feedbacks (default: RMS of the first 0.5 s)"))),
        ("--baseline", dict(action="append", default=[], metavar="[CH=]MODEL.json",
                            type=InputFile, help=(
            "baseline model (ehss identify) for channel CH, or all channels; the "
            "estimator starts from it (repeatable)"))),
        ("--batch", dict(type=float, default=0.002, metavar="S", help=(
            "after a datagram, wait up to S s for more before updating (the estimators' "
            "cost is mostly per call; default: %(default)s s)"))),
    ),
    "change detection": (
        ("--compare", dict(choices=("baseline", "recent"), default="baseline", help=(
            "test against the baseline, or against the loop --recent s ago"))),
        ("--false-alarm-hours", dict(type=float, default=24.0, metavar="H", help=(
            "mean running time between false alarms, per channel, hours: the sequential "
            "test's threshold is set for it from the statistics of the learning time "
            "(default: %(default)g, one a day)"))),
        ("--frf-db", dict(type=float, default=math.inf, metavar="DB", help=(
            "also require the RMS dB distance of the responses over the band beyond DB "
            "for an alarm (default: off; recorded all the same)"))),
        ("--gain-db", dict(type=float, default=math.inf, metavar="DB", help=(
            "also require the gain change at the band's lower edge beyond DB "
            "(default: off)"))),
        ("--pole-shift", dict(type=float, default=math.inf, metavar="FRACTION", help=(
            "also require the relative shift of the dominant pole in the band beyond "
            "FRACTION (default: off)"))),
        ("--clear", dict(type=float, default=2.0, metavar="S", help=(
            "the test below half its threshold this long clears an alarm (default: "
            "%(default)s s)"))),
        ("--learn", dict(type=float, metavar="S", help=(
            "stream time before detection; the baseline is identified over it when none "
            f"is given, and the test calibrated (default: {LEARN_S:g} s)"))),
        ("--recent", dict(type=float, default=5.0, metavar="S", help=(
            "look-back of --compare recent; a change that lasts this long is learned "
            "anew (default: %(default)s s)"))),
        ("--band", dict(nargs=2, type=float, metavar=("LO", "HI"), help=(
            "analysis band, Hz (default: the baseline's, else where the reference's "
            "spectrum is within 20 dB of its peak); with --rig --compensate also the "
            "band of the rig's reference and of its compensation (default 0.5-20 Hz "
            "for the position loop, 3-50 Hz for the acceleration loop, 1-50 Hz for "
            "the force loop; its top at most fs/3)"))),
        ("--update", dict(type=float, default=0.1, metavar="S", help=(
            "evaluation period, s of stream time (default: %(default)s)"))),
    ),
    "compensation": (
        ("--compensate", dict(choices=("preview", "causal"), help=(
            "--rig: adapt each channel's inverse-model compensator while the rig runs "
            "(preview: the reference known ahead, a drive file streamed; causal: made "
            "online); guarded updates, cross-faded in by the target's filter; runs with "
            "the terminal summary, --dashboard (a compensation panel) and --record (the "
            "desired reference as des<k> beside the drive, and each compensator event); "
            "the figures go to stderr and --report"))),
        ("--rms", dict(type=float, metavar="X", help=(
            "--compensate: RMS of the rig's reference in the loop's unit (default the "
            "rig's, with --band: 0.0005 m over 0.5-20 Hz for the position loop, whose "
            "compensated drive must stay within the rig's limits; 0.5 m/s^2 over "
            "3-50 Hz for the acceleration loop, whose online model misses its 0.5 Hz "
            "high-passes below; 1000 N over 1-50 Hz for the force loop); with --udp "
            "the RMS of the target's reference"))),
        ("--max-gain", dict(type=float, metavar="G", help=(
            "--compensate: a compensator whose drive's RMS or peak exceeds G times the "
            "reference's is refused, as `ehss compensate` refuses such a drive (default: "
            "3); the refusal says how far over it was"))),
        ("--taps", dict(type=int, metavar="N", help=(
            "--compensate: FIR taps of each compensator, 1-2048 (default 0.256 s of "
            "samples: 256 at 1 kHz, 1280 at 5 kHz); preview mode reads N/2 samples "
            "ahead. A C target compiled with a smaller EHSS_COMP_MAX_TAPS takes at most "
            "as many"))),
        ("--target", dict(metavar="HOST:PORT", help=(
            "--compensate with --udp: where the compensator datagrams go "
            "(ehss.target.datagram); the stream must carry des<k>, each channel's "
            "desired reference, beside ref<k> (drive) and fb<k>"))),
    ),
    "output": (
        ("--record", dict(metavar="FILE.h5", type=OutputFile, help=(
            "record samples, estimates and events (HDF5, readable while running; never "
            "overwritten)"))),
        ("--dashboard", dict(type=int, metavar="PORT", help=(
            "serve the dashboard on this port (0: any free port)"))),
        ("--bind", dict(default="127.0.0.1", metavar="HOST", help=(
            "dashboard address (default: %(default)s; anything else prints a warning and "
            "requires a token)"))),
        ("--quiet", dict(action="store_true", help="no terminal summary")),
        ("--stop-after", dict(type=float, metavar="S",
                              help="stop after S s of stream time")),
        ("--idle-stop", dict(type=float, metavar="S", help=(
            "--udp: stop when no datagram came for S s (after the first)"))),
        ("--report", dict(metavar="FILE.json", type=OutputFile, help=(
            "write the session's figures (counters, lag, CPU, alarms) there"))),
    ),
}


def register(sub: argparse._SubParsersAction) -> None:
    p = add_command(
        sub, "live",
        "Identify every channel of a running rig online with recursive estimation and "
        "forgetting,\ncompare each model with a baseline (or the recent past), raise "
        "alarms when it changes,\nrecord everything to HDF5 and show it in a terminal "
        "summary and a local web dashboard.",
        "ehss live --rig position --channels 2 --event 30:mass_kg=350@1 --record run.h5 "
        "--dashboard 5006")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--udp", metavar="HOST:PORT",
                     help="listen for datagrams of a real-time target (see the wire format)")
    src.add_argument("--rig", choices=("position", "acceleration", "force"),
                     help="the simulated rig, paced to the wall clock")
    src.add_argument("--replay", metavar="FILE", type=InputFile,
                     help="a recording of ehss live, or a CSV/MAT/HDF5/NPZ file with "
                     "t, ref<k>, fb<k> columns")
    for flag, kwargs in _OPTIONS["source"]:
        p.add_argument(flag, **kwargs)
    add_rig_arguments(p)
    for title, options in _OPTIONS.items():
        if title != "source":
            group = p.add_argument_group(title)
            for flag, kwargs in options:
                group.add_argument(flag, **kwargs)
    p.set_defaults(func=run)


def baselines(items: list[str], channels: tuple[str, ...]) -> dict:
    """The --baseline models per channel name."""
    from ehss.live.detect import check_baseline

    out = {}
    for item in items:
        given, sep, path = item.rpartition("=")
        ch = given if sep else None
        try:
            model = ehss.ArmaxModel.load_json(path)
        except (OSError, ValueError, KeyError) as exc:
            raise DataError(f"{path!r}: not a model file ({exc})") from None
        check_baseline(model, f"--baseline {path}")
        for name in (channels if ch is None else (ch,)):
            out[name] = model
    return out


def _source(args: argparse.Namespace) -> Any:
    from ehss.live.layout import RecordLayout, parse_fields
    from ehss.live.source import PacedSource
    from ehss.live.udp import UdpSource, parse_address

    if args.udp is not None:
        _rig_only(args, "live")
        if not args.fields:
            raise ParameterError("--udp needs --fields, the names of one sample's fields in "
                                 "wire order (e.g. t,ref1,fb1)")
        if args.fs is not None:
            _check_positive("--fs", args.fs)
        layout = RecordLayout(parse_fields(args.fields))
        allow = None if not args.allow else [a.strip() for a in args.allow.split(",")]
        try:
            return UdpSource(layout, parse_address(args.udp), fs=args.fs, allow=allow)
        except ParameterError:  # the address or its port, already named
            raise
        except ValueError as exc:
            raise ParameterError(f"--allow {args.allow!r}: {exc}") from None
    layout, samples, fs = rig_or_replay(args, "live")
    span = samples.shape[0] / fs
    if args.replay is not None and args.learn is not None and args.learn >= span:
        # an explicit --learn; the default one ends in a warning after the replay
        raise ParameterError(f"--learn {args.learn:g} s is not shorter than the record "
                             f"{str(args.replay)!r} ({span:g} s): detection would never "
                             "start")
    return PacedSource(layout, samples, fs, speed=args.speed)


def learn_s(args: argparse.Namespace) -> float:
    """Stream time before detection: --learn, or its default."""
    return LEARN_S if args.learn is None else float(args.learn)


def estimation_settings(args: argparse.Namespace) -> tuple[Any, Any]:
    """The estimator's and the change detection's settings from the options."""
    from ehss.live.channel import EstimatorSettings
    from ehss.live.detect import DetectionSettings

    est = EstimatorSettings(na=args.na, nb=args.nb, nc=args.nc, delay=args.delay,
                            method=args.method, memory_s=args.memory,
                            forgetting=args.forgetting, p0=args.p0, u_scale=args.u_scale,
                            y_scale=args.y_scale)
    det = DetectionSettings(compare=args.compare, false_alarm_hours=args.false_alarm_hours,
                            frf_db=args.frf_db, gain_db=args.gain_db,
                            pole_shift=args.pole_shift, clear_s=args.clear,
                            learn_s=learn_s(args), recent_s=args.recent,
                            band_hz=None if args.band is None else tuple(args.band))
    return est, det


class Display:
    """The terminal summary (unless --quiet) and the dashboard (with --dashboard): what
    a session publishes and logs goes there."""

    #: kinds of event printed as they happen (``compensator_change``: the compensator's
    #: trigger flagged a change of the loop, ``compensator_level`` a rise of the error it
    #: took for a new test level instead; a ``compensator`` with ``"model":
    #: "correction"`` is the correction that follows it; ``compensator_rollback``: a
    #: load that raised the error, undone)
    LOGGED = ("alarm", "clear", "message", "compensator", "compensator_refused",
              "compensator_alarm", "compensator_clear", "compensator_change",
              "compensator_level", "compensator_rollback")

    def __init__(self, args: argparse.Namespace) -> None:
        from ehss.live.summary import TerminalSummary

        self.dashboard: Any = None
        self.summary: Any = None
        if args.dashboard is not None:
            from ehss.live.dashboard import Dashboard

            self.dashboard = Dashboard(host=args.bind, port=args.dashboard)
            self.dashboard.start()
            print(f"ehss live: dashboard at {self.dashboard.url}", file=sys.stderr, flush=True)
        if not args.quiet:
            self.summary = TerminalSummary(sys.stderr)

    @property
    def publish(self) -> Callable[[Any], None] | None:
        """Where snapshots go (None when nothing shows them)."""
        return None if self.dashboard is None and self.summary is None else self._publish

    def _publish(self, snap: Any) -> None:
        if self.dashboard is not None:
            self.dashboard.publish(snap)
        if self.summary is not None:
            self.summary.update(snap)

    def log(self, event: dict) -> None:
        """Print an event worth a line as it happens."""
        if event["kind"] in self.LOGGED:
            line = json.dumps({k: v for k, v in event.items() if k != "wall"})
            if self.summary is not None:
                self.summary.note(line)
            else:
                print(f"ehss live: {line}", file=sys.stderr, flush=True)

    def close(self) -> None:
        if self.summary is not None:
            self.summary.close()
        if self.dashboard is not None:
            self.dashboard.stop()


@contextlib.contextmanager
def stop_on_sigterm() -> Iterator[threading.Event]:
    """An event set by SIGTERM (in the main thread), so that a run ends cleanly."""
    stop = threading.Event()
    main = threading.current_thread() is threading.main_thread()
    previous = signal.getsignal(signal.SIGTERM)
    if main:
        signal.signal(signal.SIGTERM, lambda *_: stop.set())
    try:
        yield stop
    finally:
        if main:
            signal.signal(signal.SIGTERM, previous)


def _check_options(args: argparse.Namespace) -> None:
    from ehss.live.recording import check_new_recording

    if args.record is not None:
        check_new_recording(args.record)
    if args.compensate is None:
        for flag, value in (("--rms", args.rms), ("--max-gain", args.max_gain),
                            ("--taps", args.taps), ("--target", args.target)):
            if value is not None:
                raise ParameterError(f"{flag} applies to --compensate only")
    if args.target is not None and args.udp is None:
        raise ParameterError("--target applies to --compensate with --udp only (the "
                             "simulated rig takes its compensator without datagrams)")
    if args.max_gain is not None:
        # a compensator's drive is bounded below by the reference itself (gain 1)
        check_real(args.max_gain, "--max-gain", lo=1.0, lo_open=True)
    if args.taps is not None:
        from ehss.target.filter import MAX_TAPS

        check_int(args.taps, "--taps", lo=1, hi=MAX_TAPS)
    if args.stop_after is not None:
        _check_positive("--stop-after", args.stop_after)
    _check_positive("--update", args.update)


def _check_at_rate(est: Any, det: Any, source: Any) -> None:
    """The settings that mean something only at the stream's rate, checked before the
    session reports itself ready when the source knows its rate (a rig or a replay): the
    memory longer than a sample and the band below Nyquist."""
    fs = source.fs
    if fs is None:
        return
    est.lam(fs)
    from ehss.signals import MAX_SAMPLES

    for option, seconds in (("--learn", det.learn_s), ("--recent", det.recent_s)):
        if seconds * fs > MAX_SAMPLES:
            raise ParameterError(f"{option} {seconds:g} holds {seconds * fs:.3g} samples at "
                                 f"{fs:g} Hz; at most {MAX_SAMPLES} are allowed")
    if det.band_hz is not None:
        check_band(det.band_hz, "--band", fs=fs)


def run(args: argparse.Namespace) -> int:
    from ehss.live.session import LiveSession

    _check_options(args)
    if args.compensate is not None:
        from ehss.cli._live_compensate import run_compensated

        _check_positive("--speed", args.speed, allow_inf=True)
        duration = RIG_DURATION_S if args.duration is None else args.duration
        _check_positive("--duration", duration)
        return run_compensated(args, duration)
    est, det = estimation_settings(args)
    source = _source(args)
    display = None
    try:
        _check_at_rate(est, det, source)
        models = baselines(args.baseline, source.layout.channels)
        display = Display(args)
        session = LiveSession(
            source, est=est, det=det, baselines=models, record=args.record,
            update_s=args.update, publish=display.publish,
            h1=display.dashboard is not None, batch_s=args.batch,
            settings={"argv": sys.argv[1:]}, log=display.log,
        )
        where = (f"listening on {source.address[0]}:{source.address[1]}"
                 if hasattr(source, "address") else "running")
        print(f"ehss live: ready, {where}", file=sys.stderr, flush=True)
        with stop_on_sigterm() as stop:
            try:
                report = session.run(duration_s=args.stop_after, stop=stop,
                                     idle_stop_s=args.idle_stop)
            except KeyboardInterrupt:
                report = None
    finally:
        source.close()
        if display is not None:
            display.close()
    if report is None:
        print("ehss live: interrupted; the recording is closed", file=sys.stderr)
        return 130
    finish(args, report)
    return 0


def finish(args: argparse.Namespace, report: Any, extra: dict | None = None) -> None:
    """The last lines of a session (samples, alarms, counters, lag; a warning for the
    channels where detection never started), and the --report file."""
    started = report.detection_started
    untested = [name for name, ok in started.items() if not ok]
    n_alarms = len([a for a in report.alarms if a["kind"] == "alarm"])
    print(f"ehss live: {report.samples} samples per channel ({report.stream_s:.1f} s), "
          f"{'no detection' if untested and not n_alarms else f'{n_alarms} alarms'}, "
          f"counters {report.counters}, lag p99 {report.lag_ms.p99:.2f} ms",
          file=sys.stderr)
    if untested:
        why = (f"the stream ended within --learn {learn_s(args):g} s"
               if report.stream_s < learn_s(args) else "see the messages above")
        print(f"ehss live: warning: detection never started on channel"
              f"{'s' if len(untested) > 1 else ''} {', '.join(untested)} ({why}): no alarm "
              "could be raised there", file=sys.stderr)
    if args.report:
        ehss.write_json(args.report, {**report.to_dict(), "versions": versions(),
                                      **(extra or {})})
