"""Filter consistency of the stored steps over the seeds: the per-step χ² ensemble test.

Pure functions of the per-step NEES and NIS the steps files hold (issue 33,
item 4), for the report's consistency figure and table. The ensemble test of
Bar-Shalom, Li & Kirubarajan 2001, *Estimation with Applications to Tracking
and Navigation*, §5.4.2: at each step the average over the N runs of a
consistent filter's NEES, times N, is χ²(6 N) (the NIS: χ²(3 N)), so the
average lies in the band of :func:`~cwrend_cli.physics.metrics.chi2_band` at
95 % of the steps. (Here, not in ``campaign.statistics``: the report reads no
campaign module, and the campaign never reads the steps back.)
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

from cwrend_cli.physics.metrics import NEES_DOF, NIS_DOF, chi2_band


def ensemble_consistency(
    frame: pd.DataFrame, by: Sequence[str], column: str, dof: int
) -> pd.DataFrame:
    """Per group of ``by`` and time ``t_s``: the ensemble mean of ``column`` against its band.

    ``frame`` holds one row per run and step (``by``, ``t_s`` and ``column``,
    e.g. ``nees`` with ``dof`` 6 or ``nis`` with 3). At each step the runs with
    a finite value count (a NIS is NaN on a dropout): ``n``, their ``mean``,
    the band of :func:`~cwrend_cli.physics.metrics.chi2_band` for ``n`` runs (``band_low``,
    ``band_high``) and whether the mean is ``inside`` it (bounds included).
    A step without a finite value is left out. Sorted by ``by`` and ``t_s``.
    """
    keys = [*by, "t_s"]
    values = frame[[*keys, column]]
    values = values[np.isfinite(values[column].to_numpy(dtype=float))]
    grouped = values.groupby(keys, sort=True, observed=True)[column]
    out = pd.DataFrame({"n": grouped.size(), "mean": grouped.mean()}).reset_index()
    low, high = chi2_band(out["n"].to_numpy(), dof)
    out["band_low"], out["band_high"] = low, high
    mean = out["mean"].to_numpy(dtype=float)
    out["inside"] = (mean >= low) & (mean <= high)
    return out


def share_inside(ensemble: pd.DataFrame, by: Sequence[str]) -> pd.DataFrame:
    """Per group of ``by``: the share of the steps of :func:`ensemble_consistency` inside the band.

    Columns ``steps`` (the steps counted), ``inside`` (the share of them
    whose ensemble mean lies in its band, 0 … 1) and ``runs`` (the most runs
    at a step: the seeds the steps come from). A consistent filter has the
    mean inside at about 95 % of its steps (each step alone: exactly 95 %).
    """
    if not by:
        ensemble = ensemble.assign(_all=0)
        by = ["_all"]
    grouped = ensemble.groupby(list(by), sort=True, observed=True)
    out = pd.DataFrame(
        {"steps": grouped.size(), "inside": grouped["inside"].mean(), "runs": grouped["n"].max()}
    ).reset_index()
    return out.drop(columns="_all", errors="ignore")


#: The per-step quantities tested, as the steps files name them, and their degrees of freedom.
TESTED: tuple[tuple[str, int], ...] = (("nees", NEES_DOF), ("nis", NIS_DOF))


def step_ensembles(steps: pd.DataFrame, nis_dof: int = NIS_DOF) -> dict[str, pd.DataFrame]:
    """The ensemble test per architecture and step of each quantity of :data:`TESTED` stored.

    ``steps``: per run and step ``arch``, ``seed``, ``t_s``, ``nees`` (and
    ``nis``, ``degradation_window`` when stored). The first time (row 0, the
    initial error against P0) is left out, as in
    :func:`~cwrend_cli.physics.metrics.mean_nees`. Each frame is that of
    :func:`ensemble_consistency` by ``arch``, plus ``nominal``: no run is in
    a degradation window at that step (True throughout when the steps do not
    say), the steps over which the NIS is judged, as
    :func:`~cwrend_cli.physics.metrics.mean_nis_nominal` judges a run's.
    ``nis_dof``: the NIS's degrees of freedom, the sensor's dimension m (3, or
    2 for angles; issue 35).
    """
    later = steps[steps["t_s"] > steps["t_s"].min()]
    out: dict[str, pd.DataFrame] = {}
    for column, dof in TESTED:
        if column not in later.columns:
            continue
        dof = nis_dof if column == "nis" else dof
        ensemble = ensemble_consistency(later, ["arch"], column, dof)
        if "degradation_window" in later.columns:
            degraded = later.loc[later["degradation_window"] >= 0, "t_s"].unique()
            ensemble["nominal"] = ~ensemble["t_s"].isin(degraded)
        else:
            ensemble["nominal"] = True
        out[column] = ensemble
    return out


def judged(ensemble: pd.DataFrame, column: str) -> pd.DataFrame:
    """The steps of ``column``'s ensemble judged against the band: the NIS's nominal ones only."""
    return ensemble[ensemble["nominal"]] if column == "nis" else ensemble
