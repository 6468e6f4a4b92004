"""How the compensation holds across what is not known exactly about a rig.

The uncertain parameters of :class:`ehss.params.RigParams` (payload, bulk modulus, valve
gain, supply pressure...) get distributions; :func:`montecarlo` draws N samples of
them reproducibly (a scrambled Sobol sequence or a Latin hypercube of
:mod:`scipy.stats.qmc`, seeded, mapped through each distribution's quantile function)
and, per sample, on the simulated rig:

1. runs the loop's identification test (a band-limited random reference) and
   identifies the loop (:func:`ehss.workflow.identify`), recording the model's verdict
   and figures (:func:`ehss.campaign.figures.loop_figures`);
2. tracks one test reference (the same for every sample) without compensation, with
   the inverse of the *nominal* model (identified once on the nominal rig) and with the
   inverse of the sample's *own* model (:func:`ehss.compensation.compensate`), and
   records each tracking error as a percentage of the reference's RMS.

A sample meets the acceptance when its tracking error with the nominal model's inverse
is at most ``max_error_pct`` or, when none is given, at most half the uncompensated
error (compensation that at least halves the error). The fraction that does is given
with its 95 % Clopper–Pearson interval.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ehss._checks import check_choice, check_int, check_real, is_real, show
from ehss.campaign.batch import _read_toml, to_plain
from ehss.campaign.engine import (
    Task,
    check_same_campaign,
    error_line,
    read_results,
    run_campaign,
    task_seed,
)
from ehss.campaign.figures import loop_figures
from ehss.errors import ParameterError

if TYPE_CHECKING:
    import polars as pl

    from ehss.identification import ArmaxModel
    from ehss.params import RigParams
    from ehss.workflow import Identification

__all__ = ["Distribution", "MonteCarloSettings", "load_montecarlo", "draw_samples",
           "montecarlo", "montecarlo_task", "acceptance_fraction", "DISTRIBUTIONS"]

#: Distributions and their parameters (``rel`` forms are relative to the nominal value).
DISTRIBUTIONS = {
    "uniform": "low, high (or rel: nominal·(1 ± rel))",
    "normal": "mean, std (or rel_std: mean = nominal, std = rel_std·nominal)",
    "lognormal": "median, sigma of ln (median default: nominal)",
}
_LOOPS = ("position",)


@dataclass(frozen=True, kw_only=True)
class Distribution:
    """One uncertain rig parameter.

    Attributes
    ----------
    name : str
        ``"group.field"`` of :class:`ehss.params.RigParams`, e.g. ``"load.mass_kg"``.
    kind : {"uniform", "normal", "lognormal"}
    a, b : float
        uniform: low, high; normal: mean, std; lognormal: median, sigma (of ln).
    """

    name: str
    kind: str
    a: float
    b: float

    def __post_init__(self) -> None:
        check_choice(self.kind, f"{self.name} distribution", DISTRIBUTIONS)
        check_real(self.a, f"{self.name} {self.kind} first parameter")
        check_real(self.b, f"{self.name} {self.kind} second parameter")
        if self.kind == "uniform" and not self.a < self.b:
            raise ParameterError(f"{self.name}: uniform low={self.a!r} must be < "
                                 f"high={self.b!r}")
        if self.kind != "uniform" and not self.b > 0:
            raise ParameterError(f"{self.name}: {self.kind} spread {self.b!r} must be > 0")
        if self.kind == "lognormal" and not self.a > 0:
            raise ParameterError(f"{self.name}: lognormal median {self.a!r} must be > 0")

    def ppf(self, q: np.ndarray) -> np.ndarray:
        """The quantile function at ``q`` in (0, 1)."""
        from scipy.stats import norm

        if self.kind == "uniform":
            return self.a + (self.b - self.a) * q
        if self.kind == "normal":
            return self.a + self.b * norm.ppf(q)
        return self.a * np.exp(self.b * norm.ppf(q))


def _nominal(params: RigParams, name: str) -> float:
    group, _, attr = name.partition(".")
    try:
        return float(getattr(getattr(params, group), attr))
    except AttributeError:
        raise ParameterError(f"unknown rig parameter {name!r}: name it 'group.field' as in "
                             "`ehss params` (e.g. 'load.mass_kg', "
                             "'actuator.bulk_modulus_pa')") from None


def _distribution(name: str, spec: Any, params: RigParams) -> Distribution:
    if not isinstance(spec, dict) or "distribution" not in spec:
        raise ParameterError(f"[parameters.{name!r}] needs 'distribution' = one of "
                             f"{', '.join(DISTRIBUTIONS)}")
    kind = spec["distribution"]
    nominal = _nominal(params, name)
    keys = set(spec) - {"distribution"}
    text = next((k for k in sorted(keys) if not is_real(spec[k])), None)
    if text is not None:
        raise ParameterError(f"[parameters.{name!r}]: {text} = {show(spec[text])} must be "
                             "a number")
    forms = {("uniform", frozenset({"low", "high"})): lambda: (spec["low"], spec["high"]),
             ("uniform", frozenset({"rel"})):
                 lambda: (nominal * (1 - spec["rel"]), nominal * (1 + spec["rel"])),
             ("normal", frozenset({"mean", "std"})): lambda: (spec["mean"], spec["std"]),
             ("normal", frozenset({"rel_std"})):
                 lambda: (nominal, nominal * spec["rel_std"]),
             ("lognormal", frozenset({"median", "sigma"})):
                 lambda: (spec["median"], spec["sigma"]),
             ("lognormal", frozenset({"sigma"})): lambda: (nominal, spec["sigma"])}
    make = forms.get((kind, frozenset(keys)))
    if make is None:
        raise ParameterError(f"[parameters.{name!r}]: {kind!r} takes "
                             f"{DISTRIBUTIONS.get(kind, 'one of ' + ', '.join(DISTRIBUTIONS))}"
                             f", not {sorted(keys)}")
    a, b = make()
    return Distribution(name=name, kind=kind, a=a, b=b)


@dataclass(frozen=True, kw_only=True)
class MonteCarloSettings:
    """A Monte Carlo campaign.

    Attributes
    ----------
    parameters : tuple of Distribution
    samples : int, default 64
    sampling : {"sobol", "lhs"}, default "sobol"
    seed : int, default 0
        Seeds the sampling, the nominal identification and every sample's task
        (:func:`ehss.campaign.engine.task_seed`).
    loop : {"position"}
    preset : str, default "default"
        Nominal rig (:func:`ehss.preset`), or ``params_file`` (TOML of ``ehss params``).
    params_file : str, optional
    duration_s : float, default 10
        Length of the identification test and of the tracking test, s.
    orders : (na, nb, nc, delay), method : str
        Identification (default the compensation demonstration's: (4, 3, 2, 1), RML).
    band_hz : (float, float), optional
        Band of the tracking reference and of the inverse; default the loop's working
        band (:data:`ehss.experiments.compensation_demo.LOOP_SETTINGS`).
    max_error_pct : float, optional
        Acceptance: largest tracking error with the nominal inverse, % of the
        reference's RMS; default: at most half the uncompensated error.
    """

    parameters: tuple[Distribution, ...]
    samples: int = 64
    sampling: str = "sobol"
    seed: int = 0
    loop: str = "position"
    preset: str = "default"
    params_file: str | None = None
    duration_s: float = 10.0
    orders: tuple[int, int, int, int] = (4, 3, 2, 1)
    method: str = "rml"
    band_hz: tuple[float, float] | None = None
    max_error_pct: float | None = None

    def __post_init__(self) -> None:
        if not self.parameters:
            raise ParameterError("no [parameters]: give at least one distribution")
        check_int(self.samples, "samples", lo=1)
        check_choice(self.sampling, "sampling", ("sobol", "lhs"))
        check_int(self.seed, "seed", lo=0)
        check_choice(self.loop, "loop", _LOOPS)
        check_real(self.duration_s, "duration_s", lo=4.0, unit="s")
        if self.max_error_pct is not None:
            check_real(self.max_error_pct, "max_error_pct", lo=0.0, lo_open=True)

    def nominal_params(self) -> RigParams:
        """The nominal rig."""
        from ehss.params import load_params, preset

        return load_params(self.params_file) if self.params_file else preset(self.preset)


_TOP = {"samples", "sampling", "seed", "loop", "preset", "params_file", "duration_s",
        "orders", "method", "band_hz", "max_error_pct", "parameters"}


def load_montecarlo(path: str | Path, *, samples: int | None = None,
                    seed: int | None = None) -> MonteCarloSettings:
    """Monte Carlo settings from TOML; ``samples`` and ``seed``, when given, replace the
    file's.

    Layout::

        samples = 500
        sampling = "sobol"            # or "lhs"
        seed = 1
        loop = "position"
        preset = "default"            # or params_file = "rig.toml"
        duration_s = 10.0
        max_error_pct = 10.0          # optional acceptance
        [parameters."load.mass_kg"]
        distribution = "uniform"
        rel = 0.2                     # or low = ..., high = ...
        [parameters."actuator.bulk_modulus_pa"]
        distribution = "normal"
        rel_std = 0.15                # or mean = ..., std = ...
        [parameters."valve.rated_flow_m3_s"]
        distribution = "lognormal"
        sigma = 0.05                  # median default: nominal

    Raises
    ------
    DataError
        If the file is missing or not TOML.
    ParameterError
        For an unknown key, parameter or distribution.
    """
    doc, where = _read_toml(path)
    unknown = sorted(set(doc) - _TOP)
    if unknown:
        raise ParameterError(f"{where}: unknown key(s) {unknown}; accepted: "
                             f"{', '.join(sorted(_TOP))}")
    kwargs: dict[str, Any] = {k: tuple(v) if isinstance(v, list) else v
                              for k, v in doc.items() if k != "parameters"}
    if "params_file" in kwargs:
        kwargs["params_file"] = str(Path(path).parent / kwargs["params_file"])
    kwargs.update({k: v for k, v in {"samples": samples, "seed": seed}.items()
                   if v is not None})
    probe = MonteCarloSettings(parameters=(Distribution(name="x", kind="uniform", a=0, b=1),),
                               **kwargs)
    nominal = probe.nominal_params()
    params = doc.get("parameters", {})
    dists = tuple(_distribution(n, s, nominal) for n, s in params.items())
    return dataclasses.replace(probe, parameters=dists)


def draw_samples(settings: MonteCarloSettings) -> np.ndarray:
    """The parameter values, shape (samples, parameters): quasi-random points of the
    unit cube (scrambled Sobol or Latin hypercube, seeded) through each quantile
    function. The first N points of a 2^m Sobol sequence keep the draw independent of
    how N is later extended."""
    from scipy.stats import qmc

    d, n = len(settings.parameters), settings.samples
    if settings.sampling == "sobol":
        engine = qmc.Sobol(d, scramble=True, seed=np.random.default_rng(settings.seed))
        unit = engine.random_base2(max(0, math.ceil(math.log2(n))))[:n]
    else:
        unit = qmc.LatinHypercube(d, seed=np.random.default_rng(settings.seed)).random(n)
    unit = np.clip(unit, 1e-12, 1 - 1e-12)  # quantile functions are finite inside (0, 1)
    return np.column_stack([p.ppf(unit[:, j]) for j, p in enumerate(settings.parameters)])


def _with_values(params: RigParams, values: dict[str, float]) -> RigParams:
    for name, v in values.items():
        group, _, attr = name.partition(".")
        params = dataclasses.replace(params, **{group: dataclasses.replace(
            getattr(params, group), **{attr: float(v)})})
    return params


def _bands(settings: MonteCarloSettings) -> tuple[dict[str, Any], tuple[float, float]]:
    from ehss.experiments.compensation_demo import LOOP_SETTINGS

    cfg = LOOP_SETTINGS[settings.loop]
    return cfg, settings.band_hz if settings.band_hz else cfg["band_hz"]


def identify_rig(params: RigParams, settings: MonteCarloSettings,
                 seeds: np.ndarray) -> Identification:
    """Run the identification test on ``params`` and identify the loop (workflow)."""
    from ehss.experiments.compensation_demo import random_reference
    from ehss.simulation import simulate
    from ehss.workflow import Estimation, Preparation, identify

    cfg, _ = _bands(settings)
    fs = float(params.timing.control_rate_hz)
    u = random_reference(settings.duration_s, fs, cfg["ident_hz"], cfg["ident_rms"],
                         int(seeds[0]))
    y = simulate(settings.loop, u, params=params, seed=int(seeds[1])).output
    return identify(u, y, fs=fs, orders=settings.orders,
                    preparation=Preparation(decimate=None),
                    estimation=Estimation(method=settings.method))


def _tracking_error_pct(model: ArmaxModel, r: np.ndarray, fs: float,
                        band: tuple[float, float], params: RigParams, loop: str,
                        seed: int) -> float:
    from ehss.compensation import compensate
    from ehss.simulation import simulate

    m = dataclasses.replace(model, band_hz=band)
    drive = compensate(m, r, fs=fs, band_hz=band, loop=loop, params=params)
    y = simulate(loop, drive, params=params, seed=seed).output
    return 100.0 * float(np.sqrt(np.mean((y - r) ** 2)) / np.sqrt(np.mean(r ** 2)))


def montecarlo_task(payload: tuple[dict[str, float], MonteCarloSettings, ArmaxModel],
                    seed: np.random.SeedSequence, out: Path) -> list[dict[str, Any]]:
    """One sample: identify its rig, track without and with both inverses (one row)."""
    import warnings

    from ehss.experiments.compensation_demo import random_reference
    from ehss.simulation import simulate

    values, settings, nominal_model = payload
    seeds = seed.generate_state(5)
    params = _with_values(settings.nominal_params(), values)
    cfg, band = _bands(settings)
    fs = float(params.timing.control_rate_hz)
    row: dict[str, Any] = dict(values)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the row records what matters
        own = identify_rig(params, settings, seeds)
        row.update(fit_pct=float(own.report.fit_pct), accepted=bool(own.accepted),
                   **loop_figures(own.model))
        r = random_reference(settings.duration_s, fs, band, cfg["test_rms"],
                             settings.seed + 1)  # one test reference for every sample
        y0 = simulate(settings.loop, r, params=params, seed=int(seeds[2])).output
        row["error_uncompensated_pct"] = 100.0 * float(np.sqrt(np.mean((y0 - r) ** 2))
                                                       / np.sqrt(np.mean(r ** 2)))
        for name, model, s in (("nominal", nominal_model, seeds[3]),
                               ("own", own.model, seeds[4])):
            try:
                row[f"error_{name}_pct"] = _tracking_error_pct(model, r, fs, band, params,
                                                               settings.loop, int(s))
                row[f"{name}_note"] = ""
            except Exception as exc:  # noqa: BLE001 - a refused drive is a result
                row[f"error_{name}_pct"] = math.nan
                row[f"{name}_note"] = error_line(exc)
    return [row]


def acceptance_fraction(frame: pl.DataFrame, settings: MonteCarloSettings) -> dict[str, Any]:
    """Samples that meet the acceptance, their fraction and its 95 % Clopper–Pearson
    interval (failed samples count as not meeting it)."""
    import polars as pl
    from scipy.stats import binomtest

    n = frame.height
    if "error_nominal_pct" not in frame.columns or n == 0:
        return {"n": n, "k": 0, "fraction": math.nan, "ci95": (math.nan, math.nan),
                "rule": "", "text": "no sample completed"}
    e = pl.col("error_nominal_pct")
    if settings.max_error_pct is not None:
        rule = f"tracking error with the nominal inverse <= {settings.max_error_pct:g} %"
        ok = e <= settings.max_error_pct
    else:
        rule = "tracking error with the nominal inverse <= half the uncompensated error"
        ok = e <= 0.5 * pl.col("error_uncompensated_pct")
    k = int(frame.select((ok & (pl.col("status") == "ok")).fill_null(False).sum()).item())
    ci = binomtest(k, n).proportion_ci(0.95, method="exact")
    text = (f"{k} of {n} samples ({100 * k / n:.1f} %, 95 % interval "
            f"{100 * ci.low:.1f}-{100 * ci.high:.1f} %) meet the acceptance: {rule}")
    return {"n": n, "k": k, "fraction": k / n, "ci95": (ci.low, ci.high), "rule": rule,
            "text": text}


def montecarlo(
    settings: MonteCarloSettings | str | Path,
    out: str | Path = "montecarlo",
    *,
    scheduler: str | None = None,
    workers: int | None = None,
    summary: bool = True,
    quiet: bool = True,
    connect_timeout_s: float = 5.0,
    samples: int | None = None,
    seed: int | None = None,
) -> pl.DataFrame:
    """Run a Monte Carlo campaign; one row per sample as a polars DataFrame.

    Parameters
    ----------
    settings : MonteCarloSettings or path of its TOML (:func:`load_montecarlo`)
    out : str or Path
        Campaign folder: ``tasks/*.parquet``, ``nominal_model.json``,
        ``settings.json``, ``summary.html``.
    scheduler, workers, quiet, connect_timeout_s
        See :func:`ehss.campaign.engine.run_campaign`.
    samples, seed : int, optional
        Replace the settings' number of samples and seed.

    Returns
    -------
    polars.DataFrame
        Columns: ``task`` (``s000000``, ``s000001``...), ``sample``, ``status``,
        ``error``, each sampled parameter, the own model's ``fit_pct``, ``accepted``
        and figures, and ``error_uncompensated_pct``, ``error_nominal_pct``, ``error_own_pct``.
    """
    from ehss.campaign.summary import write_montecarlo_summary
    from ehss.io import write_json

    if not isinstance(settings, MonteCarloSettings):
        settings = load_montecarlo(settings)
    if samples is not None:
        settings = dataclasses.replace(settings, samples=samples)
    if seed is not None:
        settings = dataclasses.replace(settings, seed=seed)
    out = Path(out)
    # more samples later extend the same draw (a Sobol prefix); nothing else may change
    same = {k: v for k, v in to_plain(settings).items()
            if k != "samples" or settings.sampling != "sobol"}
    check_same_campaign(out, same)  # before the nominal loop is identified, not after
    values = draw_samples(settings)
    names = [p.name for p in settings.parameters]
    nominal = identify_rig(settings.nominal_params(), settings,
                           task_seed(settings.seed, "nominal").generate_state(2))

    def begin(out: Path) -> None:
        if not (out / "nominal_model.json").exists():  # a resumed run keeps the first
            nominal.model.save_json(out / "nominal_model.json")

    tasks = [Task(f"s{i:06d}", (dict(zip(names, map(float, v), strict=True)),
                                      settings, nominal.model), {"sample": str(i)})
             for i, v in enumerate(values)]
    run_campaign(montecarlo_task, tasks, out, seed=settings.seed, scheduler=scheduler,
                 workers=workers, quiet=quiet, connect_timeout_s=connect_timeout_s,
                 description="montecarlo", settings=same, begin=begin)
    frame = read_results(out, sort_by=("task",))
    outcome = acceptance_fraction(frame, settings)
    write_json(out / "settings.json", {"settings": to_plain(settings),
                                       "outcome": outcome,
                                       "nominal": {"accepted": nominal.accepted,
                                                   **loop_figures(nominal.model)}})
    if summary:
        write_montecarlo_summary(frame, out / "summary.html", names, outcome)
    return frame
