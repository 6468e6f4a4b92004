"""Error and warning types of ehss.

Every error that ehss raises on purpose derives from :class:`EhssError`, so that the
command-line interface can turn it into one clear line on stderr and a non-zero exit
code instead of a traceback.
"""

from __future__ import annotations

__all__ = [
    "EhssError",
    "ParameterError",
    "DataError",
    "IdentificationError",
    "EhssWarning",
]


class EhssError(Exception):
    """Base class of all errors raised deliberately by ehss."""


class ParameterError(EhssError, ValueError):
    """A parameter, setting or test definition is impossible or out of range."""


class DataError(EhssError, ValueError):
    """Input data is missing, malformed, non-finite or inconsistent."""


class IdentificationError(EhssError, RuntimeError):
    """An identification could not produce a usable model."""


class EhssWarning(UserWarning):
    """Something worked but deserves the user's attention (unstable model, rounding...)."""
