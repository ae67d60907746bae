"""The names of everything cwrend writes: one place for the layout of a results directory.

A ``cwrend run`` directory (by default :func:`run_dir`) holds :data:`RUN_CONFIG`,
:data:`RUN_SUMMARY`, :data:`RUN_STEPS`, :data:`RUN_SOLVES`, :data:`RUN_REFERENCES` and
:data:`RUN_RECORDING`. A campaign directory (``cwrend ablate`` / ``sweep``)
holds :data:`MANIFEST`, :data:`RUNS`, :data:`EVENTS`, the statistics file,
and the datasets :data:`STEPS`, :data:`SOLVES` (``<dir>/arch=<slug>/*.parquet``),
:data:`RECORDINGS` (:func:`recording_path`) and :data:`REFERENCES`
(:func:`references_path`). The campaign writes them, the report reads them.
``cwrend compare A B`` writes :data:`COMPARE_STATS` and :data:`COMPARE_FIGURE`
into :func:`compare_dir` (beside A) unless told where.
"""

from __future__ import annotations

# Column names
#: Prefix of the ``runs.parquet`` columns holding a run's swept values.
PARAM_PREFIX = "param."
#: Prefix of a design row's unit-cube coordinate of a key in ``design.parquet``.
UNIT_PREFIX = "unit."

# A single run (``cwrend run``)
RUN_CONFIG = "config.json"
RUN_SUMMARY = "summary.parquet"
RUN_STEPS = "steps.parquet"
RUN_SOLVES = "solves.parquet"
RUN_REFERENCES = "references.parquet"
RUN_RECORDING = "recording.rrd"
#: Every file of a ``cwrend run`` directory, :data:`RUN_CONFIG` first (its presence marks a
#: complete output): what a new run into the directory replaces as one set.
RUN_FILES = (RUN_CONFIG, RUN_SUMMARY, RUN_STEPS, RUN_SOLVES, RUN_REFERENCES, RUN_RECORDING)
#: Where ``cwrend run`` writes without ``--out``, inside ``output.dir`` (:func:`run_dir`).
RUNS_DIR = "runs"

# A campaign (``cwrend ablate`` / ``cwrend sweep``)
MANIFEST = "manifest.json"
RUNS = "runs.parquet"
#: One row per grid or design point of the runs: its id and swept values (joins steps/solves).
POINTS = "points.parquet"
EVENTS = "events.jsonl"
STEPS = "steps"
SOLVES = "solves"
RECORDINGS = "recordings"
REFERENCES = "references"
ABLATION_STATS = "ablation.parquet"
SWEEP_STATS = "sweep.parquet"
#: Sensitivity indices of a ``cwrend sweep --design …`` campaign.
SENSITIVITY = "sensitivity.parquet"
#: The design matrix of a ``sweep --design`` campaign (unit sample in SALib's row order).
DESIGN = "design.parquet"
#: SALib's problem definition of a design and how cwrend analysed it.
PROBLEM = "problem.json"
#: Held (flock) by the process running the campaign; names that process.
LOCK = ".cwrend.lock"

# Two campaigns compared (``cwrend compare A B``)
COMPARE_STATS = "compare.parquet"
COMPARE_FIGURE = "compare.png"

#: Where ``cwrend report`` writes its figures and report.md, inside a results directory.
REPORT_DIR = "report"


#: Which references file holds each grid point's references: JSON lines
#: ``{"point": <id>, "file": "references/<name>.parquet"}`` (the last line of a point wins).
REFERENCES_INDEX = f"{REFERENCES}/index.jsonl"


def references_path(name: str) -> str:
    """Where the open-loop references named ``name`` go (relative).

    ``name``: ``r<digest>`` of a scenario and solver, shared by every grid
    point with them (:data:`REFERENCES_INDEX` says which points); earlier
    versions of cwrend wrote one file per point, named by its id.
    """
    return f"{REFERENCES}/{name}.parquet"


def recording_path(point: str, seed: int) -> str:
    """Where a campaign's recording of ``seed`` at grid point ``point`` goes (relative)."""
    return f"{RECORDINGS}/{point}.s{seed:06d}.rrd"


def run_dir(name: str, arch: str, seed: int) -> str:
    """Default directory of ``cwrend run`` (relative to ``output.dir``): never a campaign's.

    ``name``: ``output.name`` (default: the config file's stem); ``arch``: the
    architecture's slug, or ``multi`` for several.
    """
    return f"{RUNS_DIR}/{name}-{arch}-seed{seed}"


def compare_dir(a: str, b: str) -> str:
    """Default directory of ``cwrend compare A B`` (relative to A's parent): never inside A."""
    return f"compare-{a}-vs-{b}"
