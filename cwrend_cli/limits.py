"""The bounds cwrend puts on its inputs, in one place (issue 20).

Inputs beyond these would run out of memory or run for days before saying
anything; they are refused at the boundary (exit 2, the field or option
named), before anything runs or is written. The numbers are generous: the
paper's scenario has 800 steps, a 1,000-seed ablation 4,000 runs.
"""

from __future__ import annotations

#: Steps of one run (``scenario.horizon_s / scenario.dt_s``): a run's histories
#: take about 0.5 kB per step in memory (100,000 steps: 50 MB per run per worker).
MAX_STEPS = 100_000
#: Largest seed (and ``noise.seed``): seeds are stored as int64 in Parquet.
MAX_SEED = 2**63 - 1
#: Values of one swept key (a ``start:stop:num`` range or a list).
MAX_VALUES_PER_KEY = 10_000
#: Grid (or design) points of one campaign, unless ``--yes-large``.
MAX_POINTS = 10_000
#: Runs of one campaign invocation (points × seeds × architectures): the plan
#: and the journal of a campaign are held in memory.
MAX_RUNS = 5_000_000
#: A campaign of more runs than this says how many and how much disk before it starts.
ANNOUNCE_RUNS = 20_000
#: Size of a configuration file [bytes].
MAX_CONFIG_BYTES = 1_000_000
#: Nesting of tables and arrays in a configuration file.
MAX_NESTING = 16
#: Seeds of one campaign task (``output.seeds_per_task``): a task's runs are held in a
#: worker's memory until its files are written (about 0.2 MB of steps per run).
MAX_SEEDS_PER_TASK_SETTING = 10_000
#: Wall-time limit of one run (``output.run_timeout_s``) [s]: a day.
MAX_RUN_TIMEOUT_S = 86_400.0
#: Problems an error lists (the rest are counted): a configuration of thousands of
#: unknown keys names the first ones, not every one.
MAX_LISTED_PROBLEMS = 20
#: Keys of a ``[sweep]`` table (grid or design parameters): a grid of even 2 values
#: per key passes MAX_POINTS at 14 keys, and a design's points grow with its keys.
MAX_SWEPT_KEYS = 1_000
#: A noise file (``noise.file``, one row of n1, n2, n3 per step) is at most this many
#: bytes per step, plus NOISE_FILE_SLACK_BYTES: a CSV row of three full-precision
#: floats takes about 75 bytes, a Parquet file 24 per row plus its footer; the rest is
#: room for other columns. Anything larger is not a noise file of this scenario and is
#: refused before it is hashed or read (a sparse 3 GiB file took 64 s and 15.9 GB).
NOISE_FILE_BYTES_PER_STEP = 1024
NOISE_FILE_SLACK_BYTES = 1 << 20


def noise_file_max_bytes(n_steps: int) -> int:
    """Largest noise file accepted for a run of ``n_steps`` steps [bytes]."""
    return NOISE_FILE_SLACK_BYTES + NOISE_FILE_BYTES_PER_STEP * n_steps


def noise_file_too_large(size: int, n_steps: int) -> str | None:
    """Why a noise file of ``size`` bytes is too large for ``n_steps`` rows, or ``None``.

    The one refusal of :func:`noise_file_max_bytes`: the configuration checks a
    file's size before anything reads it, the reader what it read.
    """
    limit = noise_file_max_bytes(n_steps)
    if size <= limit:
        return None
    return (
        f"{size:,} bytes; a noise file of {n_steps:,} rows (one per step, horizon_s / dt_s) "
        f"is at most {limit:,} bytes"
    )
