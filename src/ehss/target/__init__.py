"""The return path to a real-time target: the compensator filter it runs, the datagram
that carries a compensator to it, and the same filter and decoder in portable C99
(``c/ehss_compensator.h``, ``c/ehss_compensator.c``; ``ehss target-code`` writes them out).
"""

from ehss.target import filter as _filter
from ehss.target.datagram import (
    FAULTS,
    RESULTS,
    CompensatorUpdate,
    Inbox,
    decode,
    encode,
)
from ehss.target.filter import *  # noqa: F403  (every name of the filter is offered here)

#: The filter's names, and those of the datagram a host sends a compensator with.
__all__ = [
    *_filter.__all__,
    "CompensatorUpdate",
    "FAULTS",
    "encode",
    "decode",
    "RESULTS",
    "Inbox",
]
