"""Adaptive compensation while the rig runs: the online model's inverse, sent to the target.

Each channel has its own recursive estimator of the loop from the drive it receives to
its feedback (:class:`ehss.RelsEstimator`, eqs (19)–(22) of the paper), the sliding
windows of drive, feedback and desired reference, and an
:class:`~ehss.compensation.adaptive.AdaptiveCompensator`. Every ``update_s`` of stream
time the current model is judged (:class:`~ehss.compensation.adaptive.UpdateGuard`);
a compensator that passes is sent to the target (:meth:`Target.load`), which runs it in
shadow until its start-up has died out and cross-fades it in; one that fails is not
sent, the last good one keeps running, and the refusal is logged (an alarm when a
channel that had a good compensator starts refusing, a clear when it accepts again).
A judgement runs on a worker (:attr:`CompensationSettings.judge_in`) on a copy of the
channel's windows and θ̂ (:class:`Snapshot`, :class:`Judging`), and its decision is
taken up at the next channel's turn, so that the stream's samples never wait for a
design. A change of the loop shows first in the channel's own tracking error: a quick
sequential test on it (:class:`~ehss.live.detect.TrackingTrigger`) makes the
channel's first estimator follow for a while (:meth:`ChannelAdapter.follow_change`)
and, in preview mode, has the running compensator corrected from the data since the
change (:func:`~ehss.compensation.correction.fit_correction`, a five-tap FIR folded into
it) until the full model's inverse takes over again. A rise that the trigger dates to
the fade-in of a load, while the model of before still matches the loop, is that
compensator's: the one before it is sent again (``"kind": "compensator_rollback"``),
and the trigger tests on against the level it had learnt.

The target is anything with ``load(channel, compensator, apply_index, crossfade)``,
``step(n) -> RigBlock``, ``index``, ``finished``, ``fs``, ``channels``, ``preview`` and
either the whole ``desired`` reference or its ``reference_rms``:
:class:`ehss.live.rig.SteppingRig` in process, or :class:`UdpTarget`, a remote target
whose compensators :class:`DatagramSender` sends as :mod:`ehss.target.datagram`
datagrams. ``apply_index`` counts drive samples from the start of the stream.

The package: :mod:`~ehss.live.compensate.settings` holds :class:`CompensationSettings` and
the :class:`Target` protocol; :mod:`~ehss.live.compensate.judging` a judgement
(:class:`Snapshot`, :class:`Judging`, :class:`Verdict`, :func:`seen_alike`);
:mod:`~ehss.live.compensate.adapter` a channel (:class:`ChannelAdapter`);
:mod:`~ehss.live.compensate.loop` the loop (:class:`AdaptiveLoop`,
:class:`CompensationRecord`) and its worker process; :mod:`~ehss.live.compensate.udp_target`
the remote target (:class:`UdpTarget`, :class:`DatagramSender`).
"""

from __future__ import annotations

from ehss.live.compensate.adapter import ChannelAdapter
from ehss.live.compensate.judging import Judging, Snapshot, Verdict, seen_alike
from ehss.live.compensate.loop import AdaptiveLoop, CompensationRecord
from ehss.live.compensate.settings import JUDGE_IN, CompensationSettings, Target
from ehss.live.compensate.udp_target import DatagramSender, UdpTarget

__all__ = ["CompensationSettings", "ChannelAdapter", "AdaptiveLoop", "CompensationRecord",
           "Target", "DatagramSender", "UdpTarget", "JUDGE_IN", "Snapshot", "Verdict",
           "Judging", "seen_alike"]
