"""The README's rig-health figure: a simulated year of daily records, identified by
``ehss batch``'s workflow, with the loop's figures over the year.

Run from the repository's root (a few minutes on 2 cores)::

    PYTHONPATH=src python docs/rig_health.py [FOLDER]
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import ehss.campaign as campaign
from ehss.campaign.demo import RigHealthYear, write_rig_health_archive
from ehss.campaign.summary import write_trend_png


def main() -> None:
    lab = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(tempfile.mkdtemp())
    write_rig_health_archive(lab, RigHealthYear(), workers=2)
    rows = campaign.batch([str(lab / "records" / "*.parquet")], lab / "campaign", workers=2)
    flagged = rows.filter(rows["flagged"]).select("record", "flag_reason")
    print(flagged)
    out = Path(__file__).with_name("rig_health.png")
    if out.exists():
        out.unlink()  # the figure is this script's own output
    write_trend_png(rows, out, campaign.OutlierRule())


if __name__ == "__main__":
    main()
