"""``ehss live --compensate``: adapt each channel's inverse-model compensator while the
simulated rig (or a remote target) runs, inside the live session, and report what it did.

The adaptive loop steps the target block by block; each block also goes to the live
session (identification and change detection of drive → feedback, the terminal summary,
the dashboard with its compensation panel, the recording with the desired reference
beside the drive and each compensator event), and the simulated rig runs a second time
beside it without a compensator, for the comparison."""

from __future__ import annotations

import argparse
import math
import re
import sys
import time
from collections.abc import Callable
from typing import Any

import numpy as np

import ehss
from ehss._checks import check_band, check_real
from ehss.errors import ParameterError
from ehss.live.source import Block

__all__ = ["run_compensated"]


def _taps(args: argparse.Namespace, fs: float) -> int:
    """FIR taps of each compensator: --taps, or 0.256 s of samples
    (:func:`~ehss.compensation.compensator_design.fir_taps`)."""
    from ehss.compensation.compensator_design import fir_taps
    from ehss.target import MAX_TAPS

    return fir_taps(fs, most=MAX_TAPS) if args.taps is None else int(args.taps)


def _preview(args: argparse.Namespace, fs: float) -> int:
    """Samples of reference the target's filter reads ahead: in preview mode half of
    its FIR (the other half holds the causal tail of the inverse), else none."""
    return _taps(args, fs) // 2 if args.compensate == "preview" else 0


def _rig_target(args: argparse.Namespace, duration_s: float) -> tuple[Any, Any, Any]:
    from ehss.cli._params import unstable_loop
    from ehss.live.rig import RIG_COMPENSATE_SIGNAL, SteppingRig, parse_event, rig_reference

    params = ehss.load_params(args.params) if args.params else ehss.preset(args.preset)
    why = unstable_loop(params, args.rig,
                        f"--params {args.params}" if args.params else f"--preset {args.preset}")
    if why is not None:     # its closed loop follows no reference: no inverse to adapt
        raise ParameterError(f"{why}; --compensate needs a loop that follows its reference")
    fs = params.timing.control_rate_hz if args.fs is None \
        else check_real(args.fs, "--fs", lo=0.0, lo_open=True, unit="Hz")
    rms, band = RIG_COMPENSATE_SIGNAL[args.rig]
    band = _band_at_rate(band, fs) if args.band is None \
        else check_band(args.band, "--band", fs=fs, below_nyquist=True)
    if args.rms is not None:
        rms = check_real(args.rms, "--rms", lo=0.0, lo_open=True)
    n = int(round(duration_s * fs))
    desired = np.vstack([rig_reference(n, fs, band_hz=band, rms=rms, seed=args.seed + k)
                         for k in range(1, args.channels + 1)])
    _check_within_limits(desired, fs, args.rig, params, rms, band)
    events = tuple(parse_event(e) for e in args.event)
    target = SteppingRig(args.rig, desired, fs=fs, params=params, events=events,
                         preview=_preview(args, fs), seed=args.seed)
    return target, params, band


def _band_at_rate(band: tuple[float, float], fs: float) -> tuple[float, float]:
    """The rig's default band at ``fs``: its top at most fs/3, where the inverse's band
    limit, which tapers to zero from the top to 1.5 times it, ends at the Nyquist
    frequency (:func:`ehss.compensation.design_inverse`); said when it is lowered.

    >>> _band_at_rate((0.5, 20.0), 1000.0), _band_at_rate((0.5, 20.0), 30.0)
    ((0.5, 20.0), (0.5, 10.0))
    """
    lo, hi = band
    top = fs / 3.0
    if hi <= top:
        return band
    if lo >= 0.5 * top:
        raise ParameterError(
            f"--fs {fs:g}: the rig's default band {lo:g}-{hi:g} Hz does not fit below "
            f"fs/3 = {top:.3g} Hz, where the inverse's band limit must end; give a higher "
            "--fs or a --band below it")
    print(f"ehss live: the rig's default band {lo:g}-{hi:g} Hz ends at fs/3 = {top:.3g} Hz "
          f"at --fs {fs:g} (the inverse's band limit tapers to 1.5 times its top, below "
          "fs/2); --band sets another", file=sys.stderr, flush=True)
    return lo, float(f"{top:.3g}")


def _check_within_limits(desired: np.ndarray, fs: float, loop: str, params: Any, rms: float,
                         band: tuple[float, float]) -> None:
    """Stop before the run if a channel's reference is itself beyond the rig's limits
    (:func:`ehss.compensation.check_drive` on the reference): a compensated drive
    follows the reference within the band, so every compensator would be refused and
    the run would track as it does without one (1 mm over 1–30 Hz on the position
    loop: 0.45 m/s peak velocity against 0.2 m/s, 153 refusals in 40 s)."""
    from ehss.compensation import check_drive

    for k, reference in enumerate(desired, start=1):
        try:
            check_drive(reference, reference, fs, max_gain=None, min_gain=None, loop=loop,
                        params=params)
        except ParameterError as exc:
            raise ParameterError(
                f"channel {k}'s reference ({rms:g} RMS over {band[0]:g}-{band[1]:g} Hz) is "
                f"beyond the rig's limits itself, so no compensated drive could be loaded "
                f"({exc}): lower --rms or narrow --band") from None


def _udp_target(args: argparse.Namespace) -> tuple[Any, tuple[float, float]]:
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
    band = check_band(args.band, "--band", fs=fs, below_nyquist=True)
    layout = RecordLayout(parse_fields(args.fields))
    sender = DatagramSender(parse_address(args.target))
    source = UdpSource(layout, parse_address(args.udp), fs=fs)
    try:
        target = UdpTarget(source, sender, fs=fs, preview=_preview(args, fs),
                           warn=lambda line: print(f"ehss live: warning: {line}",
                                                   file=sys.stderr, flush=True),
                           reference_rms=[rms] * len(layout.channels),
                           idle_stop_s=2.0 if args.idle_stop is None else args.idle_stop)
    except ParameterError:
        source.close()
        sender.close()
        raise
    return target, band


class _HandedSource:
    """A source the compensation hands its blocks to (:meth:`hand`); the session polls
    them. Fields: ``t``, then per channel ``ref<k>`` (the drive the loop received, the
    compensator's output and the model's input), ``fb<k>`` and ``des<k>`` (the desired
    reference, the drive without compensation)."""

    def __init__(self, channels: tuple[str, ...], fs: float,
                 counters: dict[str, int] | None = None) -> None:
        from ehss.live.layout import RecordLayout
        from ehss.live.source import new_counters

        self.layout = RecordLayout(fields=("t", *(f"{kind}{c}" for c in channels
                                                  for kind in ("ref", "fb", "des"))))
        self.fs: float | None = float(fs)
        self.counters = new_counters() if counters is None else counters
        self._own_counters = counters is None
        self._blocks: list[Block] = []
        self.finished = False

    def hand(self, first_index: int, desired: np.ndarray, drive: np.ndarray,
             feedback: np.ndarray) -> None:
        n = drive.shape[1]
        assert self.fs is not None
        cols = [(first_index + np.arange(n)) / self.fs]
        for k in range(drive.shape[0]):
            cols += [drive[k], feedback[k], desired[k]]
        self._blocks.append(Block(first_index, np.column_stack(cols), time.time()))
        if self._own_counters:
            self.counters["packets"] += 1
            self.counters["samples"] += n

    def poll(self, timeout_s: float) -> list[Block]:
        blocks, self._blocks = self._blocks, []
        return blocks

    def close(self) -> None:
        self.finished = True


class _SessionTarget:
    """The target as the adaptive loop drives it: each block it steps also goes to the
    live session (and to the monitor of the compensation panel), and, for the simulated
    rig, the same rig without a compensator steps beside it for the comparison."""

    def __init__(self, target: Any, source: _HandedSource, session: Any, monitor: Any,
                 twin: Any = None) -> None:
        self.target, self.source, self.session = target, source, session
        self.monitor, self.twin = monitor, twin
        self.fs: float = float(target.fs)
        self.channels: tuple[str, ...] = tuple(target.channels)
        self.preview: int = int(target.preview)
        self.index: int = int(target.index)
        self.loop: Any = None
        self.plain: list[np.ndarray] = []
        if hasattr(target, "desired"):
            self.desired = target.desired
        else:
            self.reference_rms = target.reference_rms

    @property
    def finished(self) -> bool:
        return bool(self.target.finished)

    def load(self, channel: int, compensator: Any, apply_index: int, crossfade: int) -> bool:
        return bool(self.target.load(channel, compensator, apply_index, crossfade))

    def step(self, n: int) -> Any:
        block = self.target.step(n)
        self.index = int(self.target.index)
        m = block.drive.shape[1]
        if not m:
            return block
        without = None
        if self.twin is not None:
            without = self.twin.step(m).feedback
            self.plain.append(without)
        self.source.hand(block.first_index, block.desired, block.drive, block.feedback)
        if self.loop is not None:
            self.monitor.follow(self.loop)   # the loads and judgements up to this block
        self.monitor.feed(block.desired, block.feedback, without)
        self.session.step(wait_s=0.0)
        return block


def run_compensated(args: argparse.Namespace, duration_s: float) -> int:
    """The ``--compensate`` run of ``ehss live`` (``--rig`` or ``--udp``): the live
    session runs inside it (terminal summary, dashboard with its compensation panel,
    recording); exit status."""

    if args.rig is None and args.udp is None:
        raise ParameterError("--compensate runs with --rig (the simulated rig's filters "
                             "take the compensators) or --udp with --target (a remote "
                             "target takes them as ehss.target datagrams)")
    if args.udp is not None:
        target, band = _udp_target(args)
        try:
            return _run(args, target, None, band)
        finally:
            target.source.close()
            target.sender.close()
    target, params, band = _rig_target(args, duration_s)
    return _run(args, target, params, band)


def _loop_event(session: Any) -> Callable[[dict], None]:
    """The adaptive loop's events into the session's log and recording (its alarms and
    clears named as the compensator's, apart from the change detection's)."""
    def log(event: dict) -> None:
        kind = event["kind"]
        if kind in ("alarm", "clear"):
            kind = f"compensator_{kind}"
        session.add_event({**event, "kind": kind}, event.get("t_s"))
    return log


def _run(args: argparse.Namespace, target: Any, params: Any, band: tuple[float, float]
         ) -> int:
    from ehss.cli._live import Display, estimation_settings, finish, stop_on_sigterm
    from ehss.live.compensate import AdaptiveLoop, CompensationSettings
    from ehss.live.monitor import CompensationMonitor
    from ehss.live.rig import SteppingRig
    from ehss.live.session import LiveSession

    settings = CompensationSettings(mode=args.compensate, band_hz=band,
                                    memory_s=args.memory,
                                    n_taps=_taps(args, float(target.fs)),
                                    guard=_guard(args)).for_stream(
        len(target.channels), float(target.fs))
    est, det = estimation_settings(args)
    counters = getattr(getattr(target, "source", None), "counters", None)
    source = _HandedSource(tuple(target.channels), target.fs, counters)
    twin = None if params is None else SteppingRig(
        args.rig, target.desired, fs=target.fs, params=params, events=target.events,
        seed=args.seed)
    display = Display(args)
    try:
        monitor = CompensationMonitor(target.channels, target.fs, band, args.compensate)
        session = LiveSession(
            source, est=est, det=det, baselines=_baselines(args, source), record=args.record,
            update_s=args.update, publish=display.publish,
            h1=display.dashboard is not None, batch_s=0.0, log=display.log,
            settings={"argv": sys.argv[1:], "compensation": settings.to_dict()},
            compensation=monitor.snapshot)
        stepped = _SessionTarget(target, source, session, monitor, twin)
        loop = AdaptiveLoop(stepped, settings, loop=args.rig if params is not None else None,
                            params=params, log=_loop_event(session))
        stepped.loop = loop
        # a remote target must run its filter with this preview, or it refuses them all
        ahead = f", {target.preview} samples ahead" if args.compensate == "preview" else ""
        print(f"ehss live: compensating ({args.compensate}, FIR of {settings.n_taps} taps"
              f"{ahead}), band {band[0]:g}-{band[1]:g} Hz", file=sys.stderr, flush=True)
        session.start()
        with stop_on_sigterm() as stop:
            try:
                rec = loop.run(speed=args.speed, stop=stop, duration_s=args.stop_after)
            except KeyboardInterrupt:
                rec = None
            finally:
                report = session.close()
    finally:
        display.close()
    if rec is None:
        print("ehss live: interrupted; the recording is closed", file=sys.stderr)
        return 130
    channels = _compare(rec, stepped.plain, getattr(target, "ignored", {}))
    finish(args, report, {"compensation": rec.settings, "channels": channels,
                          "loads": rec.loads, "decisions": rec.decisions,
                          "events": rec.events,
                          "settings": {**report.settings, "argv": sys.argv[1:]}})
    return 0


def _guard(args: argparse.Namespace) -> Any:
    """The update guard, with ``--max-gain`` if given (checked with the options)."""
    from ehss.compensation.adaptive import UpdateGuard

    return UpdateGuard() if args.max_gain is None else UpdateGuard(max_gain=args.max_gain)


def _baselines(args: argparse.Namespace, source: _HandedSource) -> dict:
    from ehss.cli._live import baselines

    return baselines(args.baseline, source.layout.channels)


def _compare(rec: Any, plain: list[np.ndarray], ignored: dict[int, str] | None = None
             ) -> dict[str, dict]:
    """Tracking RMS over the second half with and without compensation per channel,
    loads and refusals, and the channels whose remote target ran none of them
    (``ignored``, :attr:`~ehss.live.compensate.UdpTarget.ignored`); printed, and
    returned for the report."""
    n = rec.desired.shape[1]
    if plain:
        # the same rig without compensation, stepped beside it
        fb = np.concatenate(plain, axis=1)
        err = rec.desired[:, n // 2:] - fb[:, n // 2:]
    else:
        # a remote target: its first second, before any compensator
        m = min(n, int(rec.fs))
        err = rec.desired[:, :m] - rec.feedback[:, :m]
    without = np.sqrt(np.mean(err * err, axis=1))
    with_ = rec.tracking_rms(n / 2 / rec.fs, n / rec.fs)
    channels: dict[str, dict[str, Any]] = {}
    for k, name in enumerate(rec.channels):
        channels[name] = {
            "tracking_rms": float(with_[k]), "tracking_rms_without": float(without[k]),
            "loads": sum(1 for ld in rec.loads if ld["channel"] == name),
            "refusals": sum(1 for d in rec.decisions[name] if not d["accepted"]),
        }
        missed = _missed(rec.decisions[name])
        if missed:
            channels[name]["h1_misses"] = missed
        tops = [float(ld["narrowed_to_hz"]) for ld in rec.loads
                if ld["channel"] == name and "narrowed_to_hz" in ld]
        if tops:
            channels[name]["narrowed"] = {"loads": len(tops), "lowest_top_hz": min(tops),
                                          "highest_top_hz": max(tops)}
        print(f"ehss live: channel {name}: tracking RMS over the second half "
              f"{with_[k]:.4g} (without compensation {without[k]:.4g}, "
              f"{without[k] / with_[k] if with_[k] > 0 else math.inf:.1f}x), "
              f"{channels[name]['loads']} compensators loaded{_narrowed(tops)}, "
              f"{channels[name]['refusals']} refused{_said(missed)}", file=sys.stderr)
        if ignored and k in ignored:
            channels[name]["ignored_by_target"] = ignored[k]
            print(f"ehss live: {ignored[k]}", file=sys.stderr)
        offs = [ld for ld in rec.loads if ld["channel"] == name and ld["model"] == "off"]
        if offs:
            channels[name]["switched_off"] = len(offs)
            print(f"ehss live: channel {name}: compensation switched off {len(offs)}x, "
                  f"the latest at {offs[-1]['t_s']:.2f} s: {offs[-1]['text']}",
                  file=sys.stderr)
        refused = [d["reason"] for d in rec.decisions[name] if not d["accepted"]]
        if not channels[name]["loads"] and refused:
            channels[name]["latest_refusal"] = refused[-1]
            print(f"ehss live: channel {name}: no compensator was loaded; the latest "
                  f"refusal: {refused[-1]}{_hint(refused)}", file=sys.stderr)
        elif (over := _over_gain(refused)) is not None and len(over) >= _OVER_GAIN_SAID:
            # compensators ran, but most later models asked more drive than the bound:
            # the one before each ran on, which after a change of the loop is stale
            gain, bound = max(over)
            last = [d["t_s"] for d in rec.decisions[name]
                    if not d["accepted"] and _OVER_GAIN.match(d["reason"])][-1]
            channels[name]["over_gain"] = {"refusals": len(over), "max_ratio": gain,
                                           "bound": bound, "latest_t_s": float(last)}
            print(f"ehss live: channel {name}: {len(over)} of its {len(refused)} refusals "
                  f"were drives over --max-gain {bound:g}× (up to {gain:.3g}×), the latest "
                  f"at {last:.2f} s; the compensator before each ran on"
                  f"{_gain_hint(gain, bound)}", file=sys.stderr)
    return channels


def _missed(decisions: list[dict]) -> dict[str, Any] | None:
    """Where a channel's models missed the H1 estimate, if that was most of its
    refusals: how many, and the frequency at which most of them were furthest from it
    (a mode or a high-pass at the band's edge that the reference hardly excites shows
    there); None otherwise."""
    refused = [d for d in decisions if not d["accepted"]]
    worst = [float(d["h1_worst_hz"]) for d in refused if "h1_worst_hz" in d]
    if not worst or 2 * len(worst) < len(refused):
        return None
    values, counts = np.unique(np.round(worst, 9), return_counts=True)
    k = int(np.argmax(counts))
    return {"refusals": len(worst), "furthest_hz": float(values[k]),
            "furthest_there": int(counts[k])}


def _narrowed(tops: list[float]) -> str:
    """The loads narrowed below the band's top (their drive over the band was beyond
    the gain checks or the rig's limits), as part of a channel's summary line."""
    if not tops:
        return ""
    span = f"{min(tops):.3g} Hz" if min(tops) == max(tops) else \
        f"{min(tops):.3g}-{max(tops):.3g} Hz"
    return (f" ({len(tops)} of them up to {span} only: over the whole band their drive "
            "was beyond --max-gain or the rig's limits)")


def _said(missed: dict[str, Any] | None) -> str:
    """:func:`_missed` as the end of a channel's summary line."""
    if missed is None:
        return ""
    return (f", {missed['refusals']} of them as the model missed the H1 estimate, most "
            f"({missed['furthest_there']}) furthest at {missed['furthest_hz']:.3g} Hz")


#: The gain check's refusal (:func:`ehss.compensation.check_drive`): the ratio it found.
_OVER_GAIN = re.compile(
    r"the drive's (?:RMS|peak) is ([0-9.eE+-]+)× the reference's \(bound ([0-9.eE+-]+)×")


def _hint(refused: list[str]) -> str:
    """What to try when every judgement of a channel was refused, if the reasons say."""
    from ehss.compensation.adaptive import H1_DISAGREES

    h1 = sum(r.startswith(H1_DISAGREES) for r in refused)
    if 2 * h1 >= len(refused):
        # most refusals: models that miss the loop somewhere in the band, often where
        # the reference's skirt reaches a resonance it hardly excites
        # (docs/adaptive_compensation.md, "Where the defaults stop")
        return (". Most models disagreed with the H1 estimate: a --band where the "
                "reference holds its power (not where its spectrum only rolls off) lets "
                "them be validated")
    over = _over_gain(refused)
    if over is None:
        return ""
    gain, bound = max(over)
    return f". Most drives were over --max-gain {bound:g}× (up to {gain:.3g}×)" \
        + _gain_hint(gain, bound)


#: Refusals for the drive's gain a channel that ran compensators must have had, most of
#: its refusals, for its summary to say so: as many as raise a fault's alarm in a row
#: (``alarm_after``); a healthy rig's drive passes its bound but once in minutes.
_OVER_GAIN_SAID = 3


def _over_gain(refused: list[str]) -> list[tuple[float, float]] | None:
    """The (ratio, bound) of each refusal for a drive over the gain bound, if they are
    at least half of ``refused``; None otherwise. Most refusals such: inverses that need
    more gain in the band than the bound allows (a lightly damped mode there, a band
    reaching past the loop's own, a loop that a change slowed)."""
    over = [(float(m.group(1)), float(m.group(2)))
            for m in map(_OVER_GAIN.match, refused) if m]
    return over if over and 2 * len(over) >= len(refused) else None


def _gain_hint(gain: float, bound: float) -> str:
    """What to try for drives up to ``gain`` times the reference over the ``bound``: a
    narrower band, and a bound that would let them through if they are within
    ``NEAR_MISS`` times it (raised further, it would let through what the guard calls a
    fault)."""
    from ehss.compensation.adaptive import NEAR_MISS

    hint = ": a narrower --band asks less of the inverse"
    if gain <= NEAR_MISS * bound:
        hint += f"; --max-gain {math.ceil(10 * gain) / 10:g} would let them through"
    return hint
