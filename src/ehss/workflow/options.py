"""The settings of the identification workflow, as frozen objects that check themselves.

Settings that travel together are one object, declared once and shared by the library,
the command line, the order search and the report, as :class:`~ehss.workflow.Acceptance`
is:

- :class:`Preparation`: how a record becomes estimation and validation data (held-out
  fraction or separate record, band of interest, detrending, decimation);
- :class:`Estimation`: which estimator fits the model, and how the recursive ones start;
- :class:`Evaluation`: how a model is validated on the validation data (segment length
  and method of the frequency-response estimate, initial state of the simulation,
  prediction horizons);
- :class:`OrderGrid`: the candidate orders of an order search and how its pick is made.

Each field is declared with :func:`option`: its default, the check it passes through
(a function of ``(value, name)`` from :mod:`ehss._checks` or built on it, returning the
value converted) and, for the settings the command line offers, its flag and help. Each
object checks every field once, in ``__post_init__`` (:func:`check_fields`); the command
line reads the same declaration (:mod:`ehss.cli._options`), so a setting is checked the
same way wherever it is given.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Collection
from dataclasses import dataclass, field
from typing import Any

from ehss._checks import (
    as_record,
    check_band,
    check_choice,
    check_int,
    check_int_list,
    check_real,
)
from ehss.errors import ParameterError
from ehss.frequency import FRF_METHODS
from ehss.identification import INITS, METHODS
from ehss.preprocess import DETRENDS

__all__ = [
    "option",
    "or_default",
    "check_fields",
    "choice",
    "choice_option",
    "optional",
    "Preparation",
    "Estimation",
    "Evaluation",
    "OrderGrid",
    "DEFAULT_METHOD",
    "ERROR_TOLERANCE",
    "CRITERIA",
    "SAMPLES_PER_PARAMETER",
    "DEFAULT_MAX_NB",
    "INITIAL_STATES",
]

#: Estimator used when none is named: ARMAX by prediction-error minimisation started from
#: extended least squares (a batch estimate, dependable where the recursive ones stall).
DEFAULT_METHOD = "armax"

#: :func:`~ehss.workflow.select_orders` treats candidates whose validation error
#: (100 − fit, percent) is within this fraction of the best one's as equally good, and
#: picks the one with the fewest parameters. The relative standard error of an RMS over
#: N independent samples is 1/√(2N), 2 % at N = 1000; two candidates' errors on one
#: record are correlated, so 5 % is a difference that one validation record does not
#: resolve. A tolerance on the error and not on the fit: at 99.9 % a tenth of a point is
#: 2.8 times the error.
ERROR_TOLERANCE = 0.05

#: :func:`~ehss.workflow.select_orders` refuses candidates with more parameters than the
#: estimation data have samples for at this many a parameter (the rule of ten samples a
#: parameter: beyond it the estimate's variance, p/N of the noise, swamps its fit).
SAMPLES_PER_PARAMETER = 10

#: nb searched up to by default when the record supports its delay estimate.
DEFAULT_MAX_NB = 3

#: How an order search picks: the validation fit, or an information criterion.
CRITERIA = ("fit", "aic", "fpe", "mdl")

#: Initial states of the validation simulation (:func:`ehss.validation.free_run`).
INITIAL_STATES = ("estimate", "zero")


# ------------------------------------------------------------------- the declaration


def option(default: Any, *, check: Callable[[Any, str], Any], flag: str | None = None,
           help: str = "", **cli: Any) -> Any:
    """A field of a settings object: its default, its check and its command-line flag.

    Parameters
    ----------
    default
        The default value (immutable: a number, a string, a tuple or None).
    check : callable ``(value, name) -> value``
        Raises TypeError or :class:`~ehss.errors.ParameterError` naming ``name`` for a
        bad value, and returns it converted (a list to a tuple, an int to a float).
    flag : str, optional
        The command-line option that sets the field (``"--nperseg"``); None for a field
        the command line does not offer.
    help : str
        Its help text; ``%(default)s`` shows the command line's default.
    **cli
        Further :meth:`argparse.ArgumentParser.add_argument` keywords (``type``,
        ``choices``, ``metavar``, ``nargs``), ``cli_default`` for a command-line default
        other than ``default`` (None: not given, the field keeps its default), and
        ``parse``: a function ``(text, flag) -> value`` applied to what was typed.
    """
    meta: dict[str, Any] = {"check": check}
    if flag is not None:
        meta["cli"] = {"flag": flag, "help": help, **cli}
    return field(default=default, metadata=meta)


def check_fields(obj: Any) -> None:
    """Pass every field of a settings object through its check, in place (for
    ``__post_init__`` of a frozen dataclass declared with :func:`option`)."""
    for f in dataclasses.fields(obj):
        value = f.metadata["check"](getattr(obj, f.name), f.name)
        object.__setattr__(obj, f.name, value)


def choice_option(default: Any, choices: Collection[Any], *, flag: str, help: str) -> Any:
    """A field that takes one of ``choices``, offered on the command line as ``flag``."""
    return option(default, check=choice(choices), flag=flag, choices=choices, help=help)


def choice(choices: Collection[Any]) -> Callable[[Any, str], Any]:
    """The check of a field that takes one of ``choices``."""
    def check(value: Any, name: str) -> Any:
        return check_choice(value, name, choices)
    return check


def optional(check: Callable[[Any, str], Any]) -> Callable[[Any, str], Any]:
    """``check``, letting None through (a setting left to the data)."""
    def checked(value: Any, name: str) -> Any:
        return None if value is None else check(value, name)
    return checked


def _int_list(lo: int) -> Callable[[Any, str], tuple[int, ...]]:
    def check(value: Any, name: str) -> tuple[int, ...]:
        return tuple(check_int_list(value, name, lo=lo))
    return check


# -------------------------------------------------------------------------- preparation


def _validation(value: Any, name: str) -> float | tuple[Any, Any]:
    """A held-out fraction in (0, 1), or a separate record ``(u_val, y_val)``."""
    if isinstance(value, tuple):
        if len(value) != 2:
            raise ParameterError(f"{name} must be a fraction in (0, 1) or a pair "
                                 f"(u_val, y_val), not a tuple of {len(value)}")
        return as_record(*value)
    return check_real(value, name, lo=0.0, hi=1.0, lo_open=True, hi_open=True)


def _band_or_input(value: Any, name: str) -> tuple[float, float] | str | None:
    if value is None or value == "input":
        return value
    if isinstance(value, str):
        raise ParameterError(f"{name}={value!r} must be (lo, hi) in Hz, 'input' or None")
    return check_band(value, name)


def _detrend(value: Any, name: str) -> str | None:
    if value not in DETRENDS:
        raise ParameterError(f"{name}={value!r} must be 'mean', 'linear' or None")
    return value


def _decimate(value: Any, name: str) -> int | str | None:
    if value is None or value == "auto":
        return value
    if isinstance(value, str):
        raise ParameterError(f"{name}={value!r} must be 'auto', an integer >= 1 or None")
    return check_int(value, name, lo=1)


def _none_text(text: str, flag: str) -> str | None:
    """``none`` on the command line is None."""
    return None if text == "none" else text


def _decimate_text(text: str, flag: str) -> int | str | None:
    """``auto``, ``none`` or a factor, as typed after ``--decimate``."""
    t = text.strip().lower()
    if t in ("auto", "none"):
        return None if t == "none" else t
    try:
        q = int(t)
    except ValueError:
        raise ParameterError(f"{flag} {text!r} must be auto, none or an integer >= 1") \
            from None
    if q < 1:
        raise ParameterError(f"{flag} {q} must be auto, none or an integer >= 1")
    return q


@dataclass(frozen=True, kw_only=True, eq=False)
class Preparation:
    """How a record becomes estimation and validation data (:func:`~ehss.workflow.prepare`).

    Attributes
    ----------
    validation : float or (u_val, y_val), default 0.3
        A fraction in (0, 1): the end of the record kept for validation; or a separate
        validation record (same sample rate, same meaning of the columns), kept as two
        float arrays.
    band_hz : (float, float) or "input", optional
        Band of interest: where the frequency response is compared, the fit is scored
        and the decimation aims; ``hi`` must be below fs/2. ``"input"``: the band the
        estimation input excites (:func:`ehss.preprocess.excitation_band`: where its power
        spectrum is within 20 dB of its peak), read after the decimation factor is
        chosen from the record's content and kept below what the decimation leaves
        untouched. Default: up to 0.45 of the model's rate.
    detrend : {"mean", "linear", None}, default "mean"
        Removed from the estimation data and, separately, from the validation data (a
        record's operating point or drift is its own; MATLAB users do the same with
        ``detrend`` on each data set).
    decimate : "auto", int or None, default "auto"
        Decimation factor; ``"auto"`` uses :func:`ehss.preprocess.auto_decimation` on the
        estimation data (about 20× the highest frequency of interest), None or 1 none.

    Examples
    --------
    >>> Preparation(validation=0.5, decimate=None).validation
    0.5
    """

    validation: float | tuple[Any, Any] = option(
        0.3, check=_validation, flag="--holdout", type=float, metavar="FRACTION",
        cli_default=None, help="fraction at the end of the record kept for validation "
        "(default: 0.3, or none with --validate)")
    band_hz: tuple[float, float] | str | None = option(
        None, check=_band_or_input, flag="--band", nargs=2, type=float,
        metavar=("LO", "HI"), help="band of interest (Hz): where the frequency response is "
        "compared, the fit is scored and the decimation aims (default: up to 0.45 fs)")
    detrend: str | None = option(
        "mean", check=_detrend, flag="--detrend", choices=("mean", "linear", "none"),
        parse=_none_text, help="remove the mean (operating point) or a straight line from "
        "the estimation and the validation data (default: %(default)s)")
    decimate: int | str | None = option(
        "auto", check=_decimate, flag="--decimate", metavar="auto|none|N",
        parse=_decimate_text, help="decimate an oversampled record by N (zero-phase "
        "anti-alias filter) before identifying; auto: to about 10 times the highest "
        "frequency of interest; the model is then at the decimated rate "
        "(default: %(default)s)")

    def __post_init__(self) -> None:
        check_fields(self)

    @property
    def holdout(self) -> float | None:
        """The held-out fraction, or None for a separate validation record."""
        return None if isinstance(self.validation, tuple) else self.validation


# --------------------------------------------------------------------------- estimation


@dataclass(frozen=True, kw_only=True)
class Estimation:
    """Which estimator fits the model (:func:`ehss.identification.estimate`).

    Attributes
    ----------
    method : str, default :data:`DEFAULT_METHOD`
        One of :data:`ehss.identification.METHODS`.
    init : {"batch", "zero"}, default "batch"
        Start of "rels" and "rml": from the batch estimate, or the paper's zero start.
    """

    method: str = choice_option(
        DEFAULT_METHOD, METHODS, flag="--method",
        help="estimator: arx = least squares; armax = prediction-error minimisation "
        "started from extended least squares; rels = the paper's recursive extended least "
        "squares (eqs 19-22); rml = recursive maximum likelihood (default: %(default)s)")
    init: str = choice_option(
        "batch", INITS, flag="--init",
        help="start of rels/rml: from the batch (armax) estimate, or the paper's zero "
        "start (default: %(default)s; ignored by the batch methods)")

    def __post_init__(self) -> None:
        check_fields(self)


# --------------------------------------------------------------------------- evaluation


def _nperseg(value: Any, name: str) -> int:
    return check_int(value, name, lo=8)


@dataclass(frozen=True, kw_only=True)
class Evaluation:
    """How a model is validated on the validation data (:func:`ehss.validation.validate`).

    Attributes
    ----------
    nperseg : int, optional
        Segment length of the frequency-response estimate, in samples at the model's
        rate (at least 8). Default :func:`ehss.frequency.default_nperseg`.
    frf_method : {"auto", "welch", "dft"}, default "auto"
        See :func:`ehss.frequency.frf_estimate`.
    initial : {"estimate", "zero"}, default "estimate"
        Initial state of the validation simulation (:func:`ehss.validation.free_run`).
    horizons : tuple of int, default (1, 5)
        k-step prediction fits reported.
    """

    nperseg: int | None = option(
        None, check=optional(_nperseg), flag="--nperseg", type=int, metavar="N",
        help="segment length of the validation's frequency-response estimate, in samples "
        "at the model's rate (default: from the record's length and the band, at least 8 "
        "averages)")
    frf_method: str = choice_option(
        "auto", FRF_METHODS, flag="--frf-method",
        help="validation's frequency response: Welch H1, whole-record DFT (for sweeps), or "
        "whichever validates more of the band (default: %(default)s)")
    initial: str = choice_option(
        "estimate", INITIAL_STATES, flag="--initial",
        help="initial state of the validation simulation: least-squares estimate or rest "
        "(default: %(default)s)")
    horizons: tuple[int, ...] = option((1, 5), check=_int_list(1))

    def __post_init__(self) -> None:
        check_fields(self)


# ----------------------------------------------------------------------- order search


@dataclass(frozen=True, kw_only=True)
class OrderGrid:
    """The candidates of an order search and how its pick is made
    (:func:`~ehss.workflow.select_orders`).

    Attributes
    ----------
    na, nc : tuple of int, default 1-4 and 1-2
        Candidate orders of A (>= 1) and C (>= 0; ignored by "arx" and "oe").
    nb : tuple of int, optional
        Candidate orders of B (>= 0). Default: 0 to the nb the delay scan asks for (3
        when the record supports its delay estimate), as far as the record supports.
    delay : tuple of int, optional
        Candidate delays in samples of the record, each divided by the decimation
        factor for the model. Default: read from the prepared estimation data
        (:func:`ehss.identification.delay.scan_delays`).
    criterion : {"fit", "aic", "fpe", "mdl"}, default "fit"
        How the pick is made: the validation fit, or an information criterion on the
        estimation data's one-step prediction errors.
    error_tolerance : float, default :data:`ERROR_TOLERANCE`
        With ``criterion="fit"``, candidates whose validation error ``100 − fit`` is at
        most ``(1 + error_tolerance)`` times the best one's are taken as equally good,
        and the one with the fewest parameters is picked (then the first in the grid).
    """

    na: tuple[int, ...] = option((1, 2, 3, 4), check=_int_list(1))
    nb: tuple[int, ...] | None = option(None, check=optional(_int_list(0)))
    nc: tuple[int, ...] = option((1, 2), check=_int_list(0))
    delay: tuple[int, ...] | None = option(None, check=optional(_int_list(0)))
    criterion: str = choice_option(
        "fit", CRITERIA, flag="--criterion",
        help="how the best is chosen: the free-run fit on the validation data (the one "
        "identify reports), or an information criterion on the estimation data "
        "(default: %(default)s)")
    error_tolerance: float = option(
        ERROR_TOLERANCE, check=lambda v, name: check_real(v, name, lo=0.0))

    def __post_init__(self) -> None:
        check_fields(self)

    @property
    def size(self) -> int:
        """Number of candidates (two delays counted when the delays are left to the
        record, and four nb)."""
        return (len(self.na) * len(self.nb or range(4)) * len(self.nc)
                * len(self.delay or (0, 1)))


def or_default(value: Any, kind: type, name: str) -> Any:
    """``value``, a ``kind`` settings object, or ``kind()`` when it is None.

    Raises
    ------
    TypeError
        If ``value`` is something else (a dict of settings, a number).
    """
    if value is None:
        return kind()
    if not isinstance(value, kind):
        article = "an" if kind.__name__[0] in "AEIOU" else "a"
        raise TypeError(f"{name} must be {article} {kind.__name__}, not "
                        f"{type(value).__name__}")
    return value
