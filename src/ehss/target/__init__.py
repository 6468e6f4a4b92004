"""The return path to a real-time target: the compensator filter it runs, the datagram
that carries a compensator to it, and the same filter and decoder in portable C99
(``c/ehss_compensator.h``, ``c/ehss_compensator.c``; ``ehss target-code`` writes them out).
"""

from ehss.target.datagram import (
    FAULTS,
    RESULTS,
    CompensatorUpdate,
    Inbox,
    decode,
    encode,
)
from ehss.target.filter import (
    MAX_PREVIEW,
    MAX_SECTIONS,
    MAX_TAPS,
    SAMPLE_RATE_TOLERANCE,
    Compensator,
    CompensatorFilter,
    coefficient_fault,
)

__all__ = [
    "MAX_SECTIONS",
    "MAX_TAPS",
    "MAX_PREVIEW",
    "SAMPLE_RATE_TOLERANCE",
    "Compensator",
    "CompensatorFilter",
    "coefficient_fault",
    "CompensatorUpdate",
    "FAULTS",
    "encode",
    "decode",
    "RESULTS",
    "Inbox",
]
