"""A year of a rig's life on the simulated rig: the archive the rig-health demonstration
runs ``ehss batch`` on.

One record a day of the position loop (a band-limited random test, as the loop is
identified), while the oil's bulk modulus falls slowly (air entrained, the oil ageing:
ωh ∝ sqrt(βe), eq (4)) and, on one day, a valve fault (a partly clogged valve: its
rated flow, the valve gain, lower for that test). The records are written by a campaign
of their own (:func:`ehss.campaign.engine.run_campaign`), each with its date in its
metadata (``recorded_at``) and the truth (bulk modulus, valve flow) in the rows.
"""

from __future__ import annotations

import dataclasses
import datetime as dt
from pathlib import Path
from typing import Any

import numpy as np

from ehss._checks import check_int, check_real
from ehss.campaign.engine import Task, read_results, run_campaign
from ehss.errors import ParameterError
from ehss.workflow.options import check_fields, option

__all__ = ["RigHealthYear", "rig_health_task", "write_rig_health_archive"]


def _positive(value: Any, name: str) -> float:
    return check_real(value, name, lo=0.0, lo_open=True)


def _time(value: Any, name: str) -> str:
    """An ISO 8601 time (``2026-01-01T08:00:00+00:00``), as written in the records."""
    try:
        dt.datetime.fromisoformat(value)
    except (TypeError, ValueError):
        raise ParameterError(f"{name}={value!r} must be an ISO 8601 time such as "
                             "'2026-01-01T08:00:00+00:00'") from None
    return value


@dataclasses.dataclass(frozen=True, kw_only=True)
class RigHealthYear:
    """The simulated year, each field checked when it is made.

    Attributes
    ----------
    days : int, default 365
        At least one.
    duration_s : float, default 4
        Length of each day's test, s.
    bulk_modulus_loss : float, default 0.3
        Fraction of the bulk modulus lost, linearly, over the year, in [0, 1).
    fault_day : int, default 200
        The day of the valve fault (a day past the year: no fault).
    fault_flow_factor : float, default 0.6
        The valve's rated flow on that day, as a fraction of its nominal.
    rms_m : float, default 1e-4
        RMS of the 0–100 Hz random test, m.
    start : str, default "2026-01-01T08:00:00+00:00"
        The first day's record time (ISO 8601).
    """

    days: int = option(365, check=lambda v, n: check_int(v, n, lo=1))
    duration_s: float = option(4.0, check=_positive)
    bulk_modulus_loss: float = option(
        0.3, check=lambda v, n: check_real(v, n, lo=0.0, hi=1.0, hi_open=True))
    fault_day: int = option(200, check=lambda v, n: check_int(v, n, lo=0))
    fault_flow_factor: float = option(0.6, check=_positive)
    rms_m: float = option(1e-4, check=_positive)
    start: str = option("2026-01-01T08:00:00+00:00", check=_time)

    def __post_init__(self) -> None:
        check_fields(self)


def rig_health_task(payload: tuple[int, RigHealthYear, str], seed: np.random.SeedSequence,
                    out: Path) -> list[dict[str, Any]]:
    """Simulate and write one day's record; its row is the day's truth."""
    from ehss.io import write_table
    from ehss.params import preset
    from ehss.signals import band_limited_random
    from ehss.simulation import simulate

    day, year, folder = payload
    p = preset("default")
    beta = p.actuator.bulk_modulus_pa * (1 - year.bulk_modulus_loss * day / max(year.days - 1,
                                                                                  1))
    flow = p.valve.rated_flow_m3_s * (year.fault_flow_factor if day == year.fault_day
                                      else 1.0)
    p = dataclasses.replace(p, actuator=dataclasses.replace(p.actuator, bulk_modulus_pa=beta),
                            valve=dataclasses.replace(p.valve, rated_flow_m3_s=flow))
    fs = float(p.timing.control_rate_hz)
    s1, s2 = (int(v) for v in seed.generate_state(2))
    ref = band_limited_random(band_hz=(0.0, 100.0), rms=year.rms_m,
                              duration_s=year.duration_s, fs=fs, seed=s1)
    run = simulate("position", ref, params=p, seed=s2)
    when = dt.datetime.fromisoformat(year.start) + dt.timedelta(days=day)
    path = Path(folder) / f"day{day:03d}.parquet"
    write_table(path, {"t": run.t, "ref1": run.reference, "fb1": run.output},
                {"recorded_at": when.isoformat(), "loop": "position"})
    return [{"day": day, "record": str(path), "recorded_at": when.isoformat(),
             "bulk_modulus_pa": beta, "rated_flow_m3_s": flow}]


def write_rig_health_archive(folder: str | Path, year: RigHealthYear | None = None, *,
                             seed: int = 0, workers: int | None = None,
                             scheduler: str | None = None, quiet: bool = True) -> Any:
    """Write the year's records to ``folder/records`` (one Parquet file a day); returns
    the truth per day as a polars DataFrame (also in ``folder/truth/tasks``)."""
    year = year or RigHealthYear()
    folder = Path(folder)
    records = folder / "records"
    records.mkdir(parents=True, exist_ok=True)
    tasks = [Task(f"day{d:03d}", (d, year, str(records))) for d in range(year.days)]
    run_campaign(rig_health_task, tasks, folder / "truth", seed=seed, workers=workers,
                 scheduler=scheduler, quiet=quiet, description="rig-health archive")
    return read_results(folder / "truth")
