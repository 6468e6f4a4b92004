"""ehss: electro-hydraulic servo systems in Python.

Simulate a hydraulic shaking table / loading rig, close its position, acceleration and
force loops, identify the closed-loop transfer functions online with recursive extended
least squares (RELS), validate them against non-parametric frequency responses and use
them for feed-forward compensation.
"""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

from ehss.errors import DataError, EhssError, EhssWarning, IdentificationError, ParameterError
from ehss.params import RigParams, load_params, preset, save_params

try:
    __version__ = version("ehss")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = "0.0.0+unknown"

__all__ = [
    "__version__",
    "EhssError",
    "ParameterError",
    "DataError",
    "IdentificationError",
    "EhssWarning",
    "RigParams",
    "preset",
    "load_params",
    "save_params",
]
