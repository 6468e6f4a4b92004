"""What made an output: package versions, recorded in every file ehss writes."""

from __future__ import annotations

import platform
import time

__all__ = ["versions", "timestamp"]

_PACKAGES = ("numpy", "scipy", "numba", "control", "matplotlib")


def versions() -> dict[str, str]:
    """Versions of Python, ehss and the numerical packages it runs on."""
    # imported here: the metadata's reader costs tens of milliseconds, and every command
    # imports this module before it knows whether it will write anything
    from importlib.metadata import PackageNotFoundError, version

    out = {"python": platform.python_version()}
    for name in ("ehss", *_PACKAGES):
        try:
            out[name] = version(name)
        except PackageNotFoundError:  # pragma: no cover - source tree without metadata
            out[name] = "unknown"
    return out


def timestamp() -> str:
    """Local time in ISO 8601 with the UTC offset."""
    return time.strftime("%Y-%m-%dT%H:%M:%S%z")
