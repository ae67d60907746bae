"""Running cases: noise selection and the closed loop with its references.

This module decides *what* runs (architecture, seed, noise realisation) and
returns plain results; :mod:`cwrend_cli.storage` decides where they are written.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cwrend_cli import sensors, simulation
from cwrend_cli.config import Architecture, CwrendConfig


@dataclass(frozen=True)
class CaseResult:
    """The closed-loop runs of one seed and the scenario's open-loop references."""

    runs: tuple[simulation.RunResult, ...]
    references: simulation.References


def standard_normal_for(cfg: CwrendConfig, seed: int) -> np.ndarray:
    """The standard-normal realisation (N, 3) of one seed.

    ``noise.file`` replays an external realisation (validated for length and
    finiteness); otherwise the stream ``SeedSequence(noise.seed,
    spawn_key=(seed, 0))``, so realisation ``seed`` is the same in a single
    run, an ablation and a sweep, whatever worker computes it. All
    architectures of a seed share it (SPEC §6).
    """
    n_steps = cfg.scenario.n_steps
    if cfg.noise.file is not None:
        return sensors.load_noise_file(cfg.noise.file, n_steps)
    return sensors.standard_normal_stream(noise_seed_sequence(cfg.noise.seed, seed), n_steps)


def noise_seed_sequence(root_seed: int, seed: int) -> np.random.SeedSequence:
    """Stream of the measurement noise of realisation ``seed``."""
    return np.random.SeedSequence(root_seed, spawn_key=(seed, 0))


def dispersion_seed_sequence(root_seed: int, seed: int) -> np.random.SeedSequence:
    """Stream of the dispersion draws of realisation ``seed`` (independent of the noise)."""
    return np.random.SeedSequence(root_seed, spawn_key=(seed, 1))


def run_case(
    cfg: CwrendConfig,
    archs: tuple[Architecture, ...],
    seed: int,
    refs: simulation.References | None = None,
) -> CaseResult:
    """Run ``archs`` on the noise of ``seed`` (references computed if not given)."""
    noise = standard_normal_for(cfg, seed)  # validate input before any computation
    refs = refs if refs is not None else simulation.open_loop_references(cfg)
    runs = tuple(simulation.simulate(cfg, a, noise, refs, seed=seed) for a in archs)
    return CaseResult(runs, refs)
