"""Campaigns: a pure plan of runs, workers that execute tasks of it, and the driver.

The driver fans tasks out through an executor (process pool or Dask),
journals every finished task and writes the statistics files.
"""

from cwrend_cli.campaign.driver import *  # noqa: F403  (split into plan/worker/journal next)
