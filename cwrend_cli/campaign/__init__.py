"""Campaigns: a pure plan of runs, workers that execute tasks of it, the journal and the driver.

* :mod:`~cwrend_cli.campaign.plan` (pure): the grid, the runs and their tasks,
  every run's config validated once; tasks carry typed physics parameters.
* :mod:`~cwrend_cli.campaign.worker`: noise streams, the single case of
  ``cwrend run`` and the execution of one task (in a worker process).
* :mod:`~cwrend_cli.campaign.journal`: the campaign directory's layout,
  events, manifest, resume and ``--force``.
* :mod:`~cwrend_cli.campaign.driver`: fans tasks out through an executor
  (:mod:`~cwrend_cli.campaign.executors`), journals every finished task,
  writes the open-loop references and the statistics files
  (:mod:`~cwrend_cli.campaign.statistics`).
* :mod:`~cwrend_cli.campaign.guards`: what makes a run fail without raising
  (non-finite results, a time limit).
* :mod:`~cwrend_cli.campaign.design` (pure): sampled designs (LHS, Sobol,
  random) and Sobol sensitivity indices (SALib);
  :mod:`~cwrend_cli.campaign.sequential` (pure): ``--until`` targets.
* :mod:`~cwrend_cli.campaign.compare` (pure computation): two campaign
  directories paired on their shared runs (``cwrend compare``); imported by
  name, not re-exported here.

The names below are the public API.
"""

from typing import TYPE_CHECKING

from cwrend_cli.campaign.plan import (
    BASE_POINT,
    Assignment,
    CampaignPlan,
    Grid,
    NoiseSource,
    RunSpec,
    Task,
    campaign_hash,
    dispersion_seed_sequence,
    draw_dispersions,
    grid_points,
    noise_source,
    plan,
    point_id,
    run_key,
)
from cwrend_cli.lazy import lazy_attributes

#: Names of the driver and the executors, imported on first use (PEP 562): a worker
#: process imports ``cwrend_cli.campaign.worker``, hence this package, and needs neither
#: the driver nor pandas and the statistics it brings (about 0.4 s of every worker's
#: start-up). ``plan`` stays eager: the package attribute ``plan`` is the
#: function, which a later first import of the submodule would otherwise shadow.
_LAZY = {
    "CampaignStatistics": "driver",
    "CampaignSummary": "driver",
    "Progress": "driver",
    "check_references": "driver",
    "held_run_keys": "driver",
    "no_statistics": "driver",
    "run_campaign": "driver",
    "subset_statistics": "driver",
    "write_sensitivity": "driver",
    "write_statistics": "driver",
    "ExecutorKind": "executors",
    "CaseResult": "worker",
    "RunOutcome": "worker",
    "TaskOutcome": "worker",
    "execute_task": "worker",
    "noise_seed_sequence": "worker",
    "run_case": "worker",
    "seeds_to_record": "worker",
    "standard_normal": "worker",
    "standard_normal_for": "worker",
}

if TYPE_CHECKING:
    from cwrend_cli.campaign.driver import (
        CampaignStatistics,
        CampaignSummary,
        Progress,
        check_references,
        held_run_keys,
        no_statistics,
        run_campaign,
        subset_statistics,
        write_sensitivity,
        write_statistics,
    )
    from cwrend_cli.campaign.executors import ExecutorKind
    from cwrend_cli.campaign.worker import (
        CaseResult,
        RunOutcome,
        TaskOutcome,
        execute_task,
        noise_seed_sequence,
        run_case,
        seeds_to_record,
        standard_normal,
        standard_normal_for,
    )
else:
    __getattr__ = lazy_attributes(__name__, _LAZY, globals())

__all__ = [
    "BASE_POINT",
    "Assignment",
    "CampaignPlan",
    "CampaignStatistics",
    "CampaignSummary",
    "CaseResult",
    "ExecutorKind",
    "Grid",
    "NoiseSource",
    "Progress",
    "RunOutcome",
    "RunSpec",
    "Task",
    "TaskOutcome",
    "campaign_hash",
    "check_references",
    "dispersion_seed_sequence",
    "draw_dispersions",
    "execute_task",
    "grid_points",
    "held_run_keys",
    "no_statistics",
    "noise_seed_sequence",
    "noise_source",
    "plan",
    "point_id",
    "run_campaign",
    "run_case",
    "run_key",
    "seeds_to_record",
    "standard_normal",
    "standard_normal_for",
    "subset_statistics",
    "write_sensitivity",
    "write_statistics",
]
