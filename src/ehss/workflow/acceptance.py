"""What a validated model must show to be accepted, and the verdict on one."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

from ehss._checks import check_int, check_real
from ehss.validation import ValidationReport, fit_text
from ehss.workflow.options import check_fields, option

__all__ = ["Acceptance", "Verdict"]


def _positive(value: Any, name: str) -> float:
    return check_real(value, name, lo=0.0, lo_open=True)


@dataclass(frozen=True, kw_only=True)
class Acceptance:
    """What a validated model must show to be accepted: the only definition of it.

    Attributes
    ----------
    min_coherence : float, default 0.9
        Frequencies of the validation data's non-parametric estimate with a lower
        coherence are not compared (their own random error exceeds the tolerances: with
        8 averages the H1 error at γ² = 0.9 is already about 0.7 dB).
    max_magnitude_db : float, default 1.0
        Largest magnitude error against that estimate, dB.
    max_phase_deg : float, default 5.0
        Largest phase error, degrees.
    min_frf_points : int, default 3
        Fewest compared frequencies: with fewer the frequency response cannot confirm
        the model, and it is not accepted.
    min_fit_pct : float, default 90.0
        Smallest free-run simulation fit on the validation data, percent: in the band of
        interest when one is given (:func:`ehss.validation.band_fit`), raw otherwise.
    uncertainty_sigmas : float, default 2.0
        The frequency-response errors are judged after removing this many standard
        errors of the estimate itself at each point (from its coherence and averages,
        :class:`ehss.validation.FrfError`): an estimate from 8 averages at γ² = 0.9 is
        itself uncertain by 0.7 dB / 4.8°, and cannot show a model wrong by less. On a
        long, coherent record (γ² > 0.99, 10+ averages) this is a few hundredths of a dB.

    A model must also be stable (all poles strictly inside the unit circle) and its
    simulation must not diverge; these are not settings.
    """

    min_coherence: float = option(
        0.9, check=lambda v, name: check_real(v, name, lo=0.0, hi=1.0),
        flag="--min-coherence", type=float, metavar="G2",
        help="points of the validation's frequency response with a lower coherence are "
        "not compared (default: %(default)s)")
    max_magnitude_db: float = option(1.0, check=_positive)
    max_phase_deg: float = option(5.0, check=_positive)
    min_frf_points: int = option(3, check=lambda v, name: check_int(v, name, lo=1))
    min_fit_pct: float = option(90.0, check=lambda v, name: check_real(v, name, hi=100.0))
    uncertainty_sigmas: float = option(2.0,
                                       check=lambda v, name: check_real(v, name, lo=0.0))

    def __post_init__(self) -> None:
        check_fields(self)

    def judge(self, report: ValidationReport) -> Verdict:
        """The verdict on a validation report (which must have a frequency-response error,
        i.e. was computed with a band)."""
        failed: list[str] = []
        if not report.stable:
            failed.append(f"unstable (max pole radius {report.max_pole_radius:.4f})")
        if report.diverged:
            failed.append("the simulation diverges")
        elif report.fit_pct < self.min_fit_pct:
            failed.append(f"fit {fit_text(report.fit_pct)} < {self.min_fit_pct:g} %")
        e = report.frf_error
        if e is None or e.n_points < self.min_frf_points:
            n = 0 if e is None else e.n_points
            failed.append(f"{n} frequencies with coherence >= {self.min_coherence:g} "
                          f"(at least {self.min_frf_points} needed to compare)")
        else:
            k = self.uncertainty_sigmas
            mag, ph = e.beyond_uncertainty(k)
            if mag > self.max_magnitude_db:
                failed.append(f"magnitude error {mag:.2f} dB beyond {k:g} standard errors "
                              f"of the estimate > {self.max_magnitude_db:g} dB")
            if ph > self.max_phase_deg:
                failed.append(f"phase error {ph:.1f} deg beyond {k:g} standard errors of "
                              f"the estimate > {self.max_phase_deg:g} deg")
        return Verdict(accepted=not failed, failed=tuple(failed), acceptance=self)

    def summary(self) -> dict[str, Any]:
        """Plain values for JSON."""
        return dataclasses.asdict(self)


@dataclass(frozen=True, kw_only=True)
class Verdict:
    """Whether a model meets the :class:`Acceptance`, and if not, why."""

    accepted: bool
    failed: tuple[str, ...]
    acceptance: Acceptance

    def format(self) -> str:
        """One line: ``verdict: meets the acceptance (...)`` or what failed."""
        a = self.acceptance
        rule = (f"stable, fit >= {a.min_fit_pct:g} %, frequency response within "
                f"{a.max_magnitude_db:g} dB / {a.max_phase_deg:g} deg (+ {a.uncertainty_sigmas:g}"
                f" standard errors of the estimate) where coherence >= {a.min_coherence:g}")
        if self.accepted:
            return f"verdict: meets the acceptance ({rule})"
        return f"verdict: does NOT meet the acceptance ({rule}): " + "; ".join(self.failed)

    def summary(self) -> dict[str, Any]:
        """Plain values for JSON."""
        return {"accepted": self.accepted, "failed": list(self.failed),
                "acceptance": self.acceptance.summary()}

