"""Campaigns: many records or many simulated rigs, on a Dask cluster.

- :func:`batch` identifies every channel of every record of an archive the same way,
  follows the loops' figures over record time and flags the records that stand out
  (``ehss batch``);
- :func:`montecarlo` samples the rig's uncertain parameters and measures how the
  compensation holds across them (``ehss montecarlo``);

both on one engine (:mod:`ehss.campaign.engine`): tasks in a bounded window on a
``dask.distributed`` cluster, one result file per task written by the worker, failures
recorded as rows, re-runs that resume, results independent of scheduling.
"""

from __future__ import annotations

from ehss.campaign.batch import BatchSettings, batch, load_manifest
from ehss.campaign.engine import CampaignRun, Task, read_results, run_campaign, task_seed
from ehss.campaign.figures import FIGURES, loop_figures
from ehss.campaign.montecarlo import MonteCarloSettings, load_montecarlo, montecarlo
from ehss.campaign.outliers import OutlierRule
from ehss.campaign.records import Channel, Record, discover

__all__ = [
    "batch",
    "BatchSettings",
    "load_manifest",
    "montecarlo",
    "MonteCarloSettings",
    "load_montecarlo",
    "run_campaign",
    "read_results",
    "Task",
    "CampaignRun",
    "task_seed",
    "loop_figures",
    "FIGURES",
    "OutlierRule",
    "Record",
    "Channel",
    "discover",
]
