"""Adaptive compensation while the rig runs (:mod:`ehss.live.compensate.adapter`)."""

from ehss.live.compensate.adapter import *  # noqa: F403
from ehss.live.compensate.adapter import REFINE_LOAD as REFINE_LOAD
from ehss.live.compensate.adapter import __all__ as __all__
