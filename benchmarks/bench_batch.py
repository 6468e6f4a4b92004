"""Batch estimators (ARX, ARMAX, OE) against SIPPY and sysidentpy on two measured records.

Run from the project root:  .venv/bin/python benchmarks/bench_batch.py

Records: tests/data/daisy_dryer.csv and daisy_robot_arm.csv (DaISy, see their README).
Each is split in halves; the means of the first half are removed from both; every tool
fits on the first half and is scored by its free-run (simulation) fit on the second,
100 (1 − ‖y − ŷ‖/‖y − ȳ‖). ehss and SIPPY models are scored by the same function,
:func:`ehss.validation.simulation_fit`, from the least-squares initial state
(MATLAB ``compare``'s default); sysidentpy's ``predict`` takes its initial conditions
from the first measured outputs instead, so its fit is computed over validation samples
``max_lag``..end.

All tools fit the same structure (the orders ``ehss order`` picks with its default
method on that record, reported in the table); sysidentpy's FROLS additionally chooses
its own terms by AIC among lags up to na and nb + 1. Times are the best of ``--repeat``
runs after one warm-up call (SIPPY's first call imports sympy/casadi). Everything in the
printed table comes from this one run.
"""

from __future__ import annotations

import argparse
import platform
import sys
import time
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from ehss.identification import ArmaxModel, estimate, select_order  # noqa: E402
from ehss.io import read_columns, sample_rate  # noqa: E402
from ehss.validation import nrmse_fit as fit_percent  # noqa: E402
from ehss.validation import simulation_fit  # noqa: E402


def free_run_fit(model: Any, u: np.ndarray, y: np.ndarray) -> float:
    """Free-run fit from the least-squares initial state (MATLAB ``compare``'s default)."""
    return simulation_fit(model, u, y, initial="estimate")


RECORDS = {
    "dryer": ("daisy_dryer.csv", range(1, 6), range(0, 5), (1, 2)),
    "robot arm": ("daisy_robot_arm.csv", range(2, 9, 2), range(1, 8, 2), (2,)),
}


def halves(name: str) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray], float]:
    table = read_columns(ROOT / "tests" / "data" / name, ["u", "y"], time_column="t")
    dt = 1.0 / sample_rate(table, None)
    u, y = table["u"], table["y"]
    n = u.size // 2
    u, y = u - np.mean(u[:n]), y - np.mean(y[:n])
    return (u[:n], y[:n]), (u[n:], y[n:]), dt




def timed(fn: Callable[..., Any], repeat: int) -> tuple[Any, float]:
    fn()  # warm-up
    best, out = np.inf, None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return out, best


def tf_model(G: Any, dt: float) -> ArmaxModel:
    """A python-control discrete SISO transfer function as an ArmaxModel (B/A part)."""
    num = np.atleast_1d(np.squeeze(G.num[0][0])).astype(float)
    den = np.atleast_1d(np.squeeze(G.den[0][0])).astype(float)
    return ArmaxModel.from_paper_form(num, den, dt=dt)


def run_record(label: str, spec: Any, repeat: int) -> list[tuple]:
    name, na_g, nb_g, nc_g = spec
    (u, y), (uv, yv), dt = halves(name)
    rows = []

    def workflow() -> Any:
        sel = select_order(u, y, na=list(na_g), nb=list(nb_g), nc=list(nc_g), dt=dt,
                           score=lambda m: free_run_fit(m, uv, yv))
        b = sel.best
        return estimate(u, y, method=sel.method, na=b.na, nb=b.nb, nc=b.nc, delay=b.delay,
                        dt=dt), b

    (model, best), t = timed(workflow, repeat)
    na, nb, nc, d = best.na, best.nb, best.nc, best.delay
    orders = f"({na},{nb},{nc},{d})"
    rows.append((label, "ehss default workflow (order → armax)", orders,
                 free_run_fit(model, uv, yv), t))
    for method in ("arx", "armax", "oe"):
        m, t = timed(lambda method=method: estimate(u, y, method=method, na=na, nb=nb, nc=nc,
                                                    delay=d, dt=dt), repeat)
        rows.append((label, f"ehss {method}", orders, free_run_fit(m, uv, yv), t))

    from sippy_unipi import system_identification  # type: ignore[import-not-found]

    def sippy(method: str, **kw: Any) -> Any:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return system_identification(y, u, method, tsample=dt, **kw)

    for method, kw in (("ARX", {"ARX_orders": [na, nb + 1, d - 1]}),
                       ("ARMAX", {"ARMAX_orders": [na, nb + 1, nc, d - 1]}),
                       ("ARMAX", {"ARMAX_orders": [na, nb + 1, nc, d - 1],
                                  "ARMAX_mod": "OPT"}),
                       ("OE", {"OE_orders": [nb + 1, na, d - 1]})):
        tag = method + (" (OPT)" if kw.get("ARMAX_mod") == "OPT" else "")
        try:
            s, t = timed(lambda method=method, kw=kw: sippy(method, **kw), repeat)
            rows.append((label, f"SIPPY {tag}", orders, free_run_fit(tf_model(s.G, dt), uv, yv), t))
        except Exception as exc:  # noqa: BLE001 - a failing third-party fit is reported
            rows.append((label, f"SIPPY {tag}", orders, float("nan"), float("nan")))
            print(f"SIPPY {tag} failed on {label}: {exc}", file=sys.stderr)

    from sysidentpy.basis_function import Polynomial  # type: ignore[import-not-found]
    from sysidentpy.model_structure_selection import FROLS  # type: ignore[import-not-found]
    from sysidentpy.parameter_estimation import LeastSquares  # type: ignore[import-not-found]

    def frols() -> Any:
        model = FROLS(ylag=na, xlag=list(range(d, d + nb + 1)), order_selection=True,
                      info_criteria="aic", estimator=LeastSquares(),
                      basis_function=Polynomial(degree=1))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            model.fit(X=u.reshape(-1, 1), y=y.reshape(-1, 1))
        return model

    m, t = timed(frols, repeat)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        yhat = m.predict(X=uv.reshape(-1, 1), y=yv.reshape(-1, 1))
    lag = m.max_lag
    rows.append((label, "sysidentpy FROLS (linear, AIC terms)", orders,
                 fit_percent(yv[lag:], np.asarray(yhat).reshape(-1)[lag:]), t))
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    from importlib.metadata import version

    import sippy_unipi  # noqa: F401 - fail early if the bench extra is missing
    import sysidentpy  # type: ignore[import-not-found]

    print(f"# {platform.python_version()}, numpy {np.__version__}, "
          f"sippy-unipi {version('sippy-unipi')}, sysidentpy {sysidentpy.__version__}, "
          f"{platform.machine()}")
    print()
    print("| record | estimator | orders (na,nb,nc,d) | free-run fit % | time (s) |")
    print("| --- | --- | --- | ---: | ---: |")
    for label, spec in RECORDS.items():
        for rec, est, orders, f, t in run_record(label, spec, args.repeat):
            print(f"| {rec} | {est} | {orders} | {f:.2f} | {t:.3f} |")


if __name__ == "__main__":
    main()
