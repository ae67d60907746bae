"""The cwrend configuration models: one pydantic model, validated once at the boundary.

A run is described by a TOML file whose tables mirror :class:`CwrendConfig`
(``[scenario]``, ``[estimator]``, ``[schedule]``, ``[guidance]``, ``[solver]``,
``[degradation]``, ``[truth]``, ``[actuator]``, ``[noise]``, ``[output]``). Every
field has a default equal to the paper's scenario (Candan & Servadio, AAS
26-893, Table 1, plus the settings of the authors' code that the paper leaves out:
docs/method.md), so an empty file is the paper scenario. The file is read by
:func:`~cwrend_cli.config.io.load_config`, ``--set key=value`` overrides are
applied (:mod:`cwrend_cli.config.overrides`), and the result is validated into
frozen model objects that the rest of the package receives; nothing downstream
re-reads or re-validates raw dictionaries.

This module holds the models only, with the validators they use (field
lengths, covariance normalisation, cross-field rules); the texts of their
errors are built in :mod:`cwrend_cli.config.messages`.

Units everywhere (the paper's, Table 1): km, s, km/s, km/s²; covariances in the matching
squared units. Field names carry their unit (``horizon_s``, ``u_max_km_s2``).
"""

from __future__ import annotations

import math
import re
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Literal, Self

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    SerializerFunctionWrapHandler,
    Strict,
    ValidationInfo,
    field_validator,
    model_serializer,
    model_validator,
)

from cwrend_cli.config.messages import fmt_num, rules_error, table_value_problem
from cwrend_cli.limits import (
    MAX_RUN_TIMEOUT_S,
    MAX_RUNS,
    MAX_SEED,
    MAX_SEEDS_PER_TASK_SETTING,
    MAX_STEPS,
    MAX_SWEPT_KEYS,
    NOISE_FILE_BYTES_PER_STEP,
    NOISE_FILE_SLACK_BYTES,
    noise_file_too_large,
)
from cwrend_cli.physics import params
from cwrend_cli.physics.params import covariance_matrix

if TYPE_CHECKING:
    import numpy as np

__all__ = [
    "ActuatorConfig",
    "ConstraintsConfig",
    "CorridorConfig",
    "CwrendConfig",
    "DegradationConfig",
    "DegradationWindow",
    "Dispersion",
    "EstimatorConfig",
    "GuidanceConfig",
    "KeepOutBodyConfig",
    "KeepOutConfig",
    "NoiseConfig",
    "OutputConfig",
    "ScenarioConfig",
    "ScheduleConfig",
    "SensorConfig",
    "SolverConfig",
    "TargetConfig",
    "TruthConfig",
]

# Numbers are strict: a TOML string "1e-3" or a boolean is not silently turned
# into a float (ints are still accepted and stored as floats).
Float = Annotated[float, Strict()]
Int = Annotated[int, Strict()]
Vec3 = tuple[Float, Float, Float]
Vec6 = tuple[Float, Float, Float, Float, Float, Float]
Angle = Annotated[float, Strict(), Field(ge=-180, le=180)]
#: An angle of the chief's orbit [deg]: up to a turn either way.
OrbitAngleDeg = Annotated[float, Strict(), Field(ge=-360, le=360)]

# Bounds of the physical quantities (issue 36 item 7). Generous for any rendezvous
# the CW model describes, finite so that no accepted value overflows the filter or
# the solver (a value of 1e308 ran for minutes, or recorded inf NIS as an ok run).
#: |position| [km]: CW relative motion holds for separations far below the orbit
#: radius (6,800 km for the paper's orbit; the paper starts 31 km away).
POSITION_MAX_KM = 1e4
#: |velocity| [km/s]: above the speed of any Earth orbit (7.9 km/s at the surface).
VELOCITY_MAX_KM_S = 10.0
#: Diagonal (variance) of a covariance [km², km²/s²]: σ up to POSITION_MAX_KM, VELOCITY_MAX_KM_S.
POSITION_VARIANCE_MAX_KM2 = POSITION_MAX_KM**2
VELOCITY_VARIANCE_MAX_KM2_S2 = VELOCITY_MAX_KM_S**2
#: Smallest variance [km², km²/s²]: σ = 1e-15 km (or km/s), below the float resolution
#: of the paper's 31 km state (7e-15 km).
VARIANCE_MIN = 1e-30
#: Times [s]: 1e6 s (11.6 days) at the coarsest step still has at most MAX_STEPS steps
#: at dt = 10 s; any rendezvous horizon is shorter.
TIME_MAX_S = 1e6
#: Homotopy parameter ε [-] (paper Eq. 10: the smoothing width of the switching function,
#: which is of order 1; ε_max = 1 in paper Table 1): at 100 the smoothed
#: plan is half thrust within 1 %.
EPS_MAX = 100.0
#: Dimensionless weights, scales and gains of the schedule and sensor faults [-].
GAIN_MAX = 1e6
#: Control acceleration [km/s²]: about 10 g, bounds u_max and the minimum thrust.
ACCEL_MAX_KM_S2 = 0.1

#: Mean, spread and ends of a dispersion draw [the key's unit]: the largest bound of
#: any value it may set.
DISPERSION_MAX = POSITION_VARIANCE_MAX_KM2
#: A mean or end of a dispersion draw [the key's unit]: within ±DISPERSION_MAX.
DispersionValue = Annotated[float, Strict(), Field(ge=-DISPERSION_MAX, le=DISPERSION_MAX)]

#: A factor on a true measurement variance [-] (a degradation window's r_scale).
RScale = Annotated[float, Strict(), Field(ge=1e-6, le=GAIN_MAX)]
#: A probability [-] (a degradation window's outlier_probability).
Probability = Annotated[float, Strict(), Field(ge=0, le=1)]
#: A factor on the Gaussian noise of an outlier [-].
OutlierScale = Annotated[float, Strict(), Field(ge=0, le=1e3)]
PositionKm = Annotated[float, Strict(), Field(ge=-POSITION_MAX_KM, le=POSITION_MAX_KM)]
VelocityKmS = Annotated[float, Strict(), Field(ge=-VELOCITY_MAX_KM_S, le=VELOCITY_MAX_KM_S)]
#: A relative state [x, y, z, ẋ, ẏ, ż] [km, km/s], each entry bounded.
State6 = tuple[PositionKm, PositionKm, PositionKm, VelocityKmS, VelocityKmS, VelocityKmS]
# A covariance as given: n diagonal entries, or a full n×n matrix (rows).
Covariance = tuple[Float, ...] | tuple[tuple[Float, ...], ...]

#: The defaults of every section: the paper's scenario (paper Table 1 plus the settings of
#: the authors' code that the paper leaves out, docs/method.md), defined once with the
#: physics parameters.
_PAPER = params.Problem()

# Tolerance for "a whole multiple of dt" (a convention of cwrend: times are whole
# numbers of steps; not in the paper).
_MULTIPLE_TOL = 1e-9
_SAFE_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]*")
_NOISE_SUFFIXES = (".csv", ".parquet", ".pq")


class _FrozenModel(BaseModel):
    """Base of every config model: unknown keys rejected, immutable, finite floats."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False, defer_build=True)


def _is_whole_multiple(value: float, step: float) -> bool:
    """True when ``value / step`` is an integer within :data:`_MULTIPLE_TOL`."""
    ratio = value / step
    return abs(ratio - round(ratio)) < _MULTIPLE_TOL


def _check_length(value: Any, n: int) -> Any:
    """Before-validator for fixed-length vectors: a clear message for a wrong length."""
    if isinstance(value, (list, tuple)) and len(value) != n:
        raise ValueError(f"must have {n} entries (got {len(value)})")
    return value


# ---------------------------------------------------------------------------
# Sections
# ---------------------------------------------------------------------------


class ScenarioConfig(_FrozenModel):
    """Rendezvous geometry and timing (paper Eqs. 3–4, Table 1).

    x0 is given in paper Sec. "Numerical Results and Discussion". The mean motion
    is the authors' code's (a convention of cwrend; not in the paper).
    """

    mean_motion_rad_s: Float = Field(
        _PAPER.scenario.mean_motion_rad_s,
        ge=1e-6,
        le=1.3e-3,
        description="CW mean motion n of the target orbit, in [1e-6, 1.3e-3] [rad/s] (an orbit "
        "at Earth's surface has 1.24e-3; 1e-6 is a 73-day period, beyond GEO's 7.3e-5)",
    )
    horizon_s: Float = Field(
        _PAPER.scenario.horizon_s,
        gt=0,
        le=TIME_MAX_S,
        description="rendezvous horizon T, in (0, 1e6] [s], a whole multiple of dt_s",
    )
    dt_s: Float = Field(
        _PAPER.scenario.dt_s,
        ge=1e-3,
        le=3600,
        description="simulation / filter / control-hold step Δt, in [1e-3, 3600] [s]",
    )
    x0: State6 = Field(
        _PAPER.scenario.x0,
        description="initial relative state [x, y, z, ẋ, ẏ, ż] [km, km/s]; positions within "
        "±1e4 km, velocities within ±10 km/s",
    )
    xf: State6 = Field(
        _PAPER.scenario.xf,
        description="target terminal state [x, y, z, ẋ, ẏ, ż] [km, km/s]; positions within "
        "±1e4 km, velocities within ±10 km/s",
    )
    u_max_km_s2: Float = Field(
        _PAPER.scenario.u_max_km_s2,
        ge=1e-9,
        le=ACCEL_MAX_KM_S2,
        description="maximum control acceleration, in [1e-9, 0.1] (about 10 g) [km/s²]",
    )

    @field_validator("x0", "xf", mode="before")
    @classmethod
    def _six_entries(cls, value: Any) -> Any:
        return _check_length(value, 6)

    @model_validator(mode="after")
    def _horizon_on_grid(self) -> Self:
        if self.horizon_s / self.dt_s > MAX_STEPS + 0.5:
            raise rules_error(
                [
                    (
                        "horizon_s",
                        self.horizon_s,
                        f"gives {fmt_num(self.horizon_s / self.dt_s)} steps of dt_s = "
                        f"{fmt_num(self.dt_s)}; at most {MAX_STEPS:,} steps per run",
                    )
                ]
            )
        if not _is_whole_multiple(self.horizon_s, self.dt_s):
            raise rules_error(
                [
                    (
                        "horizon_s",
                        self.horizon_s,
                        f"must be a whole multiple of dt_s ({fmt_num(self.dt_s)})",
                    )
                ]
            )
        return self

    @property
    def n_steps(self) -> int:
        """Number of steps N = T/Δt (the grid is t_k = k Δt, k = 0..N)."""
        return round(self.horizon_s / self.dt_s)


#: Largest variance of each diagonal entry of R (3 positions), Q and P0 (3 positions,
#: 3 velocities) [km², km²/s²]; an off-diagonal entry of a positive-definite matrix is
#: bounded by its diagonal (|c_ij| <= sqrt(c_ii c_jj)), so these bound every entry.
_R_VARIANCE_MAX = (POSITION_VARIANCE_MAX_KM2,) * 3
_STATE_VARIANCE_MAX = _R_VARIANCE_MAX + (VELOCITY_VARIANCE_MAX_KM2_S2,) * 3


def _check_variances(diagonal: Sequence[float], maxima: Sequence[float]) -> None:
    """Refuse a variance outside [VARIANCE_MIN, its maximum] (issue 36 item 7)."""
    for i, (d, top) in enumerate(zip(diagonal, maxima, strict=True)):
        if d <= 0.0:
            raise ValueError("must be positive definite (diagonal entries must be > 0)")
        if not VARIANCE_MIN <= d <= top:
            unit = "km" if top == POSITION_VARIANCE_MAX_KM2 else "km/s"
            raise ValueError(
                f"diagonal entry {i} = {fmt_num(d)} must be in [{fmt_num(VARIANCE_MIN)}, "
                f"{fmt_num(top)}] {unit}² (σ at most {fmt_num(math.sqrt(top))} {unit})"
            )


def _normalise_covariance(
    value: Any, maxima: Sequence[float]
) -> tuple[float, ...] | tuple[tuple[float, ...], ...]:
    """Check a covariance given as n diagonal entries or an n×n matrix (n = len(maxima)).

    Returns the canonical stored form: the diagonal tuple when the matrix is
    diagonal, otherwise the full matrix as a tuple of row tuples, so that two
    spellings of the same matrix validate (and hash) identically. Each
    diagonal entry must lie in [:data:`VARIANCE_MIN`, its entry of ``maxima``].
    """
    n = len(maxima)
    shape_msg = f"must have {n} entries (diagonal) or be a {n}x{n} matrix"
    numpy = sys.modules.get("numpy")  # an array exists only once numpy is loaded (issue 17:
    if numpy is not None and isinstance(value, numpy.ndarray):  # the config imports no numpy)
        value = value.tolist()
    if not isinstance(value, (list, tuple)):
        raise ValueError(shape_msg)
    rows_are_seq = [isinstance(r, (list, tuple)) for r in value]
    if value and all(rows_are_seq):
        if len(value) != n or any(len(r) != n for r in value):
            raise ValueError(shape_msg)
        entries = [e for r in value for e in r]
    elif not any(rows_are_seq):
        if len(value) != n:
            raise ValueError(shape_msg)
        entries = list(value)
    else:
        raise ValueError(shape_msg)
    for e in entries:
        if isinstance(e, bool) or not isinstance(e, (int, float)) or not math.isfinite(e):
            raise ValueError("entries must be finite numbers")

    if not any(rows_are_seq):
        diag = tuple(float(e) for e in value)
        _check_variances(diag, maxima)
        return diag

    import numpy as np  # a full matrix only: a config of diagonals loads no numpy

    mat = np.array(value, dtype=np.float64)
    _check_variances([float(d) for d in np.diag(mat)], maxima)
    scale = float(np.max(np.abs(mat)))
    if float(np.max(np.abs(mat - mat.T))) > 1e-12 * scale:
        raise ValueError("must be symmetric")
    try:
        # Cholesky succeeds exactly when the symmetric matrix is positive definite.
        np.linalg.cholesky(mat)
    except np.linalg.LinAlgError:
        raise ValueError("must be positive definite") from None
    off_diagonal = mat - np.diag(np.diag(mat))
    if not np.any(off_diagonal):
        return tuple(float(d) for d in np.diag(mat))
    return tuple(tuple(float(e) for e in row) for row in mat)


class EstimatorConfig(_FrozenModel):
    """Kalman filter covariances (paper Eqs. 11–21; defaults: paper Table 1).

    Each covariance is given either as its diagonal (a list of n positive
    numbers) or as a full symmetric positive-definite n×n matrix.
    """

    r_nominal_km2: Covariance = Field(
        _PAPER.estimator.r_nominal_km2,
        description="nominal measurement covariance R (3, or 3x3) [km²]; 1e-6 is a 1 m σ; "
        "diagonal entries in [1e-30, 1e8] km²",
        json_schema_extra={
            "diagonal_minimum": VARIANCE_MIN,
            "diagonal_maximum": list(_R_VARIANCE_MAX),
        },
    )
    q_process: Covariance = Field(
        _PAPER.estimator.q_process,
        description="discrete process-noise covariance Q (6, or 6x6) [km², km²/s²]; diagonal "
        "entries in [1e-30, 1e8] km² (positions) and [1e-30, 100] km²/s² (velocities)",
        json_schema_extra={
            "diagonal_minimum": VARIANCE_MIN,
            "diagonal_maximum": list(_STATE_VARIANCE_MAX),
        },
    )
    p0: Covariance = Field(
        _PAPER.estimator.p0,
        description="initial estimate covariance P0 (6, or 6x6) [km², km²/s²]; diagonal "
        "entries in [1e-30, 1e8] km² (positions) and [1e-30, 100] km²/s² (velocities)",
        json_schema_extra={
            "diagonal_minimum": VARIANCE_MIN,
            "diagonal_maximum": list(_STATE_VARIANCE_MAX),
        },
    )

    @field_validator("r_nominal_km2", mode="before")
    @classmethod
    def _check_r(cls, value: Any) -> Any:
        return _normalise_covariance(value, _R_VARIANCE_MAX)

    @field_validator("q_process", "p0", mode="before")
    @classmethod
    def _check_q_p0(cls, value: Any) -> Any:
        return _normalise_covariance(value, _STATE_VARIANCE_MAX)

    initial_error: State6 = Field(
        _PAPER.estimator.initial_error,
        description="initial estimate minus true initial state [km, km/s]; the paper's "
        "filter starts at the truth (zeros). A dispersion target for initial errors. "
        "Positions within ±1e4 km, velocities within ±10 km/s.",
    )

    process_noise: Literal["fixed", "from_actuator", "adaptive"] = Field(
        _PAPER.estimator.process_noise,
        description="process noise Q_k of each step: 'fixed' (q_process, the paper's), "
        "'from_actuator' (q_process + the actuator errors' at the commanded thrust) or "
        "'adaptive' (Sage-Husa estimate, floored at q_process) [-]",
    )
    q_forgetting: Float = Field(
        _PAPER.estimator.q_forgetting,
        ge=0.5,
        lt=1.0,
        description="forgetting factor b of the adaptive process noise (memory about "
        "1/(1 - b) steps), in [0.5, 1); read with process_noise = 'adaptive' [-]",
    )

    @field_validator("initial_error", mode="before")
    @classmethod
    def _six_errors(cls, value: Any) -> Any:
        return _check_length(value, 6)

    @model_serializer(mode="wrap")
    def _without_default_process_noise(self, handler: SerializerFunctionWrapHandler) -> Any:
        # the process-noise fields at their defaults are left out of the resolved tree (the
        # config and campaign hashes are computed from it): existing hashes unchanged (issue 33)
        out = handler(self)
        if isinstance(out, dict):
            for name in ("process_noise", "q_forgetting"):
                if getattr(self, name) == getattr(_PAPER.estimator, name):
                    out.pop(name, None)
        return out

    def r_nominal_matrix(self) -> np.ndarray:
        """R_nominal as a new 3×3 float64 array [km²]."""
        return covariance_matrix(self.r_nominal_km2)

    def q_matrix(self) -> np.ndarray:
        """Q as a new 6×6 float64 array [km², km²/s²]."""
        return covariance_matrix(self.q_process)

    def p0_matrix(self) -> np.ndarray:
        """P0 as a new 6×6 float64 array [km², km²/s²]."""
        return covariance_matrix(self.p0)


class ScheduleConfig(_FrozenModel):
    """Innovation-adaptive homotopy schedule (paper Eqs. 24–26, Table 1).

    Score ``s = min(max(NIS - nis_offset, 0) + kappa_mtf ρ, score_max)``, low-pass
    ``s̄_k = score_lowpass s̄_{k-1} + (1 - score_lowpass) s_k``, target
    ``ε* = eps_min + (eps_max - eps_min)(1 - exp(-beta s̄))`` (``eps_min`` when
    ``s̄ < deadband``; clipped at ``eps_saturation`` if set), applied
    ``ε_k = (1 - alpha_eps) ε_{k-1} + alpha_eps ε*``.
    """

    beta: Float = Field(
        _PAPER.schedule.beta,
        gt=0,
        le=1e3,
        description="score-to-homotopy sensitivity β, in (0, 1e3] [1/score] (paper 0.25; at "
        "1e3 a score of 0.01 already moves ε* to within e⁻¹⁰ of ε_max)",
    )
    nis_offset: Float = Field(
        _PAPER.schedule.nis_offset,
        ge=0,
        le=GAIN_MAX,
        description="NIS offset m subtracted before scoring, in [0, 1e6] [-] (paper: the "
        "measurement dimension, 3)",
    )
    score_lowpass: Float = Field(
        _PAPER.schedule.score_lowpass,
        ge=0,
        lt=1,
        description="score low-pass coefficient ρ_s, in [0, 1) [-]",
    )
    kappa_mtf: Float = Field(
        _PAPER.schedule.kappa_mtf,
        ge=0,
        le=GAIN_MAX,
        description="weight κ_MTF of the MTF ratio in the score, in [0, 1e6] [-] (paper 12)",
    )
    score_max: Float = Field(
        _PAPER.schedule.score_max,
        gt=0,
        le=GAIN_MAX,
        description="cap on the instantaneous score, in (0, 1e6] [-] (paper 50)",
    )
    eps_min: Float = Field(
        _PAPER.schedule.eps_min,
        ge=0,
        le=EPS_MAX,
        description="lower end ε_min of the homotopy map, in [0, 100] [-]",
    )
    eps_max: Float = Field(
        _PAPER.schedule.eps_max,
        gt=0,
        le=EPS_MAX,
        description="upper end ε_max of the map; adaptive runs start here; in (0, 100] [-] "
        "(paper 1)",
    )
    alpha_eps: Float = Field(
        _PAPER.schedule.alpha_eps,
        gt=0,
        le=1,
        description="blending factor α_ε of the applied ε, in (0, 1] [-]",
    )
    deadband: Float = Field(
        _PAPER.schedule.deadband,
        ge=0,
        le=GAIN_MAX,
        description="filtered score below which ε* = eps_min; 0 disables it; in [0, 1e6] [-]",
    )
    eps_saturation: Float | None = Field(
        _PAPER.schedule.eps_saturation,
        ge=0,
        le=EPS_MAX,
        description="upper clip of ε*, within [eps_min, eps_max]; unset disables it [-]",
    )
    eps_fixed: Float = Field(
        _PAPER.schedule.eps_fixed,
        ge=0,
        le=EPS_MAX,
        description="ε held by the fixed architectures, in [0, 100] (paper: 0, bang-bang) [-]",
    )

    @model_validator(mode="after")
    def _eps_ordering(self) -> Self:
        problems: list[tuple[str, Any, str]] = []
        if self.eps_min > self.eps_max:
            problems.append(
                ("eps_min", self.eps_min, f"must be <= eps_max ({fmt_num(self.eps_max)})")
            )
        sat = self.eps_saturation
        if sat is not None and not (self.eps_min <= sat <= self.eps_max):
            problems.append(
                (
                    "eps_saturation",
                    sat,
                    f"must lie in [eps_min, eps_max] = "
                    f"[{fmt_num(self.eps_min)}, {fmt_num(self.eps_max)}]",
                )
            )
        if problems:
            raise rules_error(problems)
        return self


class GuidanceConfig(_FrozenModel):
    """Receding-horizon re-solve settings (paper Sec. "Receding-Horizon Indirect Guidance").

    The timing and the hold are conventions of cwrend, not in the paper
    (docs/method.md). ``resolve_timing = "correct"`` solves from the estimate at t_{k+1} with
    remaining horizon T - t_{k+1}; ``"reference"`` reproduces the authors' code
    (T - t_k, then the solved costate propagated one step). ``hold`` chooses
    how the plan's control is held over a step: sampled at its start (authors)
    or averaged over the step.
    """

    t_resolve_s: Float = Field(
        _PAPER.guidance.t_resolve_s,
        gt=0,
        le=TIME_MAX_S,
        description="re-solve interval, in (0, 1e6] [s] (a whole multiple of scenario.dt_s)",
    )
    t_min_rem_s: Float = Field(
        _PAPER.guidance.t_min_rem_s,
        ge=0,
        le=TIME_MAX_S,
        description="no re-solve once the remaining horizon is <= this, in [0, 1e6] [s]",
    )
    resolve_timing: Literal["correct", "reference"] = Field(
        _PAPER.guidance.resolve_timing,
        description="re-solve timing: 'correct' or the authors' 'reference' [-]",
    )
    hold: Literal["sample", "mean"] = Field(
        _PAPER.guidance.hold,
        description="control hold over a step: 'sample' (start) or 'mean' (average) [-]",
    )
    method: Literal["shooting", "socp"] = Field(
        _PAPER.guidance.method,
        description="re-solve method of the architectures that do not name one: 'shooting' "
        "(costate) or 'socp' (held controls of the smoothed min-fuel cone program) [-]",
    )


class SolverConfig(_FrozenModel):
    """Shooting solver settings (paper Eqs. 8–10; the settings are cwrend's, not in the paper)."""

    fallback: Literal["chain", "none"] = Field(
        _PAPER.solver.fallback,
        description="on failure of the primary solver: try the fallback chain or not [-]",
    )
    on_infeasible: Literal["keep", "min_miss"] = Field(
        _PAPER.solver.on_infeasible,
        description="when the convex check says x_f is unreachable: keep the propagated "
        "costate, or steer to the minimum-miss solution [-]",
    )
    success_residual: Float = Field(
        _PAPER.solver.success_residual,
        gt=0,
        le=POSITION_MAX_KM,
        description="a solve succeeds when ||x(T) - x_f|| is below this, in (0, 1e4] [km, km/s]",
    )
    tol_pos_km: Float = Field(
        _PAPER.solver.tol_pos_km,
        gt=0,
        le=POSITION_MAX_KM,
        description="solver tolerance on position, in (0, 1e4] [km]",
    )
    tol_vel_km_s: Float = Field(
        _PAPER.solver.tol_vel_km_s,
        gt=0,
        le=VELOCITY_MAX_KM_S,
        description="solver tolerance on velocity, in (0, 10] [km/s]",
    )
    max_iter: Int = Field(
        _PAPER.solver.max_iter,
        ge=1,
        le=1000,
        description="maximum solver iterations per solve, in [1, 1000] [-] (paper 50; each "
        "costs about 0.1 ms, and every re-solve may make them)",
    )
    quadrature_nodes: Int = Field(
        _PAPER.solver.quadrature_nodes,
        ge=4,
        le=64,
        description="quadrature nodes per step for the control integral [-]",
    )
    switching_newton_steps: Int = Field(
        _PAPER.solver.switching_newton_steps,
        ge=0,
        le=1000,
        description="at eps = 0, steps of the switching-time Newton tried before the dual "
        "ascent (its answer is kept only when the full evaluation confirms it); 0 = the "
        "dual ascent alone, the solver of cwrend 0.1 [-]",
    )


class DegradationWindow(_FrozenModel):
    """One sensor-degradation interval (the paper gives no values: docs/method.md).

    The window is active when ``start_s <= t <= end_s`` (both ends included).
    While active, the true measurement covariance is ``r_scale * R_nominal``
    and ``bias_km`` is added to each measurement. Where windows overlap, the
    later one in the list applies, so the paper's windows [250, 325] and
    [325, 400] give the second one at t = 325 s. Outside every window the true
    covariance is R_nominal and there is no bias. Sensor faults (issue 15,
    item 3; all off by default; :class:`cwrend_cli.physics.params.Window`):
    dropouts, outliers (a contaminated Gaussian) and a bias drifting as a
    random walk while the window is active.
    """

    start_s: Float = Field(
        ge=0, le=TIME_MAX_S, description="window start time (inclusive), in [0, 1e6] [s]"
    )
    end_s: Float = Field(
        ge=0,
        le=TIME_MAX_S,
        description="window end time (inclusive), >= start_s, <= scenario.horizon_s [s]",
    )
    r_scale: RScale | tuple[RScale, ...] = Field(
        1.0,
        description="true measurement covariance = r_scale * R_nominal, in [1e-6, 1e6]; one "
        "value for every component or one per measurement component (3; 2 for "
        "sensor.model = 'angles') [-] (paper 300)",
    )
    bias_km: tuple[PositionKm, PositionKm, PositionKm] = Field(
        (0.0, 0.0, 0.0),
        description="measurement bias added while active, each within ±1e4 km [km]",
    )
    dropout_probability: Float = Field(
        0.0, ge=0, le=1, description="probability of no measurement on a step; 1 = blackout [-]"
    )
    outlier_probability: Probability | tuple[Probability, ...] = Field(
        0.0,
        description="probability that a step's noise is an outlier, in [0, 1]; one value "
        "(every component an outlier together) or one per measurement component (each on "
        "its own draw) [-]",
    )
    outlier_scale: OutlierScale | tuple[OutlierScale, ...] = Field(
        1.0,
        description="factor on the Gaussian noise of an outlier, in [0, 1e3]; one value or "
        "one per measurement component [-]",
    )
    bias_drift_km_per_sqrt_s: Float = Field(
        0.0,
        ge=0,
        le=10.0,
        description="random-walk intensity q of the bias: N(0, q² Δt) per step and axis, in "
        "[0, 10] [km/√s] (10 drifts 10 km in a second of window)",
    )
    bias_range_km: PositionKm = Field(
        0.0,
        description="sensor.model = 'range_bearing': bias of the measured range, within "
        "±1e4 km [km]",
    )
    bias_angles_deg: tuple[Angle, Angle] = Field(
        (0.0, 0.0),
        description="sensor.model = 'range_bearing' or 'angles': bias of the measured "
        "(azimuth, elevation), each in [-180, 180] [deg]",
    )

    @field_validator("bias_angles_deg", mode="before")
    @classmethod
    def _two_entries(cls, value: Any) -> Any:
        return _check_length(value, 2)

    @model_serializer(mode="wrap")
    def _without_sensor_fields_when_off(self, handler: SerializerFunctionWrapHandler) -> Any:
        # the nonlinear sensors' biases (issue 35) left out at zero: hashes unchanged
        out = handler(self)
        if isinstance(out, dict):
            if out.get("bias_range_km") == 0.0:
                out.pop("bias_range_km")
            if tuple(out.get("bias_angles_deg", ())) == (0.0, 0.0):
                out.pop("bias_angles_deg")
        return out

    @field_validator("bias_km", mode="before")
    @classmethod
    def _three_entries(cls, value: Any) -> Any:
        return _check_length(value, 3)

    @model_validator(mode="after")
    def _ordered(self) -> Self:
        if self.end_s < self.start_s:
            raise rules_error(
                [("end_s", self.end_s, f"must be >= start_s ({fmt_num(self.start_s)})")]
            )
        return self


_PAPER_WINDOWS = tuple(
    DegradationWindow(
        start_s=w.start_s,
        end_s=w.end_s,
        r_scale=w.r_scale,
        bias_km=w.bias_km,
        dropout_probability=w.dropout_probability,
        outlier_probability=w.outlier_probability,
        outlier_scale=w.outlier_scale,
        bias_drift_km_per_sqrt_s=w.bias_drift_km_per_sqrt_s,
        bias_range_km=w.bias_range_km,
        bias_angles_deg=w.bias_angles_deg,
    )
    for w in _PAPER.degradation.windows
)


class DegradationConfig(_FrozenModel):
    """Measurement degradation schedule; an empty list means none.

    The default windows are not in the paper (docs/method.md).
    """

    windows: tuple[DegradationWindow, ...] = Field(
        _PAPER_WINDOWS,
        description="degradation windows; later entries win where they overlap",
    )


class TruthConfig(_FrozenModel):
    """The dynamics the true relative state obeys (issue 15); guidance and filter: see [model].

    ``model``: ``"cw"`` (the design model itself, the paper's setting),
    ``"two_body"`` (exact nonlinear relative motion about a Keplerian chief,
    in its rotating local-vertical frame) or ``"j2"`` (both spacecraft under
    two-body + J2 of EGM2008, integrated in an inertial frame). The chief's
    osculating orbit at t = 0: semi-major axis a = (μ/n²)^{1/3} from
    ``scenario.mean_motion_rad_s`` and the elements below (default: circular,
    equatorial). Axes: x radial, y along-track, z cross-track.
    """

    model: Literal["cw", "two_body", "j2"] = Field(
        _PAPER.truth.model,
        description="truth dynamics: 'cw' (the design model), 'two_body' or 'j2' [-]",
    )
    eccentricity: Float = Field(
        _PAPER.truth.eccentricity, ge=0, lt=1, description="chief eccentricity e, in [0, 1) [-]"
    )
    true_anomaly_deg: OrbitAngleDeg = Field(
        _PAPER.truth.true_anomaly_deg,
        description="chief true anomaly f at t = 0, in [-360, 360] [deg]",
    )
    inclination_deg: Float = Field(
        _PAPER.truth.inclination_deg,
        ge=0,
        le=180,
        description="chief inclination i, in [0, 180] [deg]",
    )
    raan_deg: OrbitAngleDeg = Field(
        _PAPER.truth.raan_deg,
        description="chief right ascension of the ascending node Ω, in [-360, 360] [deg]",
    )
    arg_latitude_deg: OrbitAngleDeg = Field(
        _PAPER.truth.arg_latitude_deg,
        description="chief argument of latitude u = ω + f at t = 0, in [-360, 360] [deg]",
    )


class ModelConfig(_FrozenModel):
    """The design model of the guidance and of the filter (issue 33); CW by default.

    ``"cw"``: Clohessy–Wiltshire (the paper's). ``"ss"``: Schweighart–Sedwick
    (J2, constant coefficients) about the chief's orbit: radius a = (μ/n²)^{1/3}
    from ``scenario.mean_motion_rad_s`` and inclination ``truth.inclination_deg``.
    ``"ya"``: Yamanaka–Ankersen, the exact transition about the Keplerian chief
    of ``[truth]``: eccentricity ``truth.eccentricity``, true anomaly
    ``truth.true_anomaly_deg`` at t = 0. Both read the chief from ``[truth]``,
    so they need a truth that flies one (``truth.model`` ``"two_body"`` or
    ``"j2"``). The filter also takes ``"ekf_two_body"`` and ``"ekf_j2"``: an
    extended Kalman filter on the nonlinear two-body (two-body + J2) relative
    dynamics about the same chief, with the same need. Without the section
    every number and hash is as before.
    """

    guidance: Literal["cw", "ss", "ya"] = Field(
        _PAPER.model.guidance,
        description="design model of the re-solves: 'cw', 'ss' (J2) or 'ya' (eccentric) [-]",
    )
    filter: Literal["cw", "ss", "ya", "ekf_two_body", "ekf_j2"] = Field(
        _PAPER.model.filter,
        description="model of the Kalman filter's prediction: 'cw', 'ss', 'ya', or an "
        "extended Kalman filter on the nonlinear dynamics 'ekf_two_body' or 'ekf_j2' [-]",
    )


class SensorConfig(_FrozenModel):
    """What the chaser measures (issue 35; ``[sensor]``); the paper's relative position by default.

    ``"position"``: the relative position [km], noise ``estimator.r_nominal_km2``
    (paper Eq. 13). ``"range_bearing"``: range [km], azimuth and elevation of the
    target seen from the chaser; ``"angles"``: azimuth and elevation only (a
    camera); both updated by an extended Kalman filter, with σ_range =
    ``sigma_range_km`` + ``sigma_range_fraction`` × range and σ_angle =
    ``sigma_angle_deg`` (:mod:`cwrend_cli.physics.measurement_models`). With the
    default the section is left out of the resolved config, so every number and
    hash is as before.
    """

    model: Literal["position", "range_bearing", "angles"] = Field(
        _PAPER.sensor.model,
        description="measurement: 'position', 'range_bearing' or 'angles' [-]",
    )
    sigma_range_km: Float = Field(
        _PAPER.sensor.sigma_range_km,
        gt=0,
        le=POSITION_MAX_KM,
        description="range_bearing: constant part of the range σ, in (0, 1e4] [km]",
    )
    sigma_range_fraction: Float = Field(
        _PAPER.sensor.sigma_range_fraction,
        ge=0,
        le=1,
        description="range_bearing: the range σ grows by this fraction of the range, in [0, 1] [-]",
    )
    sigma_angle_deg: Float = Field(
        _PAPER.sensor.sigma_angle_deg,
        gt=0,
        le=10,
        description="range_bearing and angles: σ of the azimuth and of the elevation, in "
        "(0, 10] [deg]",
    )


class ActuatorConfig(_FrozenModel):
    """Actuator errors between the commanded and the applied control (issue 15); all off by default.

    The truth receives the applied control, the filter predicts with the
    command. For step k, with the command c of ``delay_steps`` steps earlier
    (zero before): nothing if ‖c‖ < ``min_thrust_km_s2``; otherwise magnitude
    ‖c‖ (1 + ``magnitude_bias`` + ``magnitude_sigma`` z_k), clipped to
    [0, u_max (1 + ``magnitude_bias``)], direction rotated by the fixed
    misalignment R = R_z(γ) R_y(β) R_x(α) (``misalignment_deg`` = (α, β, γ)
    about x radial, y along-track, z cross-track) and then tilted by a
    random angle with two N(0, ``pointing_sigma_deg``²) components
    perpendicular to the thrust (:class:`cwrend_cli.physics.params.Actuator`).
    The per-step draws come from their own stream, ``SeedSequence(noise.seed,
    spawn_key=(seed, 2))``.
    """

    magnitude_bias: Float = Field(
        _PAPER.actuator.magnitude_bias,
        gt=-1,
        le=10,
        description="fixed thrust-magnitude scale error, a fraction (0.01 = +1 %), in (-1, 10] [-]",
    )
    magnitude_sigma: Float = Field(
        _PAPER.actuator.magnitude_sigma,
        ge=0,
        le=10,
        description="per-step thrust-magnitude noise σ, a fraction of the command, in [0, 10] [-]",
    )
    misalignment_deg: tuple[Angle, Angle, Angle] = Field(
        _PAPER.actuator.misalignment_deg,
        description="fixed misalignment: rotation angles about x, y, z, applied x then y then z "
        "(R = Rz Ry Rx), each in [-180, 180] [deg]",
    )
    pointing_sigma_deg: Float = Field(
        _PAPER.actuator.pointing_sigma_deg,
        ge=0,
        le=180,
        description="per-step pointing noise σ per axis perpendicular to the thrust [deg]",
    )
    min_thrust_km_s2: Float = Field(
        _PAPER.actuator.min_thrust_km_s2,
        ge=0,
        le=ACCEL_MAX_KM_S2,
        description="commands below this magnitude produce no thrust, in [0, 0.1] and <= "
        "scenario.u_max_km_s2 [km/s²]",
    )
    delay_steps: Int = Field(
        _PAPER.actuator.delay_steps,
        ge=0,
        le=MAX_STEPS,
        description="actuation delay in whole steps, < the run's number of steps [-]",
    )

    @field_validator("misalignment_deg", mode="before")
    @classmethod
    def _three_angles(cls, value: Any) -> Any:
        return _check_length(value, 3)


class NoiseConfig(_FrozenModel):
    """Measurement-noise realisation (v_k of paper Eq. 13; a convention of cwrend).

    Either drawn from ``seed`` or read from ``file``: a CSV or Parquet table
    with columns n1, n2, n3 of standard-normal draws, one row per step, scaled
    by chol(true R) at use. A relative ``file`` is resolved against the config
    file's directory when loaded; the stored value is the absolute path.
    """

    seed: Int = Field(
        0, ge=0, le=MAX_SEED, description="root seed of the standard-normal realisation [-]"
    )
    file: str | None = Field(
        None,
        description="external standard-normal realisation (CSV/Parquet, columns n1,n2,n3; "
        "one row per step; at most 1 MiB + 1 kB per step) [-]",
        json_schema_extra={
            "max_bytes": f"{NOISE_FILE_SLACK_BYTES} + {NOISE_FILE_BYTES_PER_STEP} per step"
        },
    )

    @field_validator("file")
    @classmethod
    def _resolve_file(cls, value: str | None, info: ValidationInfo) -> str | None:
        if value is None:
            return None
        if not value.strip():
            raise ValueError("must be a non-empty path")
        if "\x00" in value:
            raise ValueError("must not contain a NUL character")
        path = Path(value).expanduser()
        if not path.is_absolute():
            base = (info.context or {}).get("base_dir")
            path = (Path(base) if base is not None else Path.cwd()) / path
        path = path.resolve()
        if path.suffix.lower() not in _NOISE_SUFFIXES:
            raise ValueError(f"must be a CSV or Parquet file ({', '.join(_NOISE_SUFFIXES)})")
        if not path.is_file():
            raise ValueError(f"file not found: {path}")
        return str(path)


class OutputConfig(_FrozenModel):
    """Where results go: ``<dir>/<name>/...``."""

    dir: str = Field("results", min_length=1, description="results root directory [-]")
    name: str | None = Field(
        None,
        description="run/campaign name, a plain file name (default: the config file's stem) [-]",
    )
    steps_seeds: Int | None = Field(
        None,
        ge=0,
        le=MAX_SEED,
        description="campaigns: write per-step data (steps/ dataset) only for seeds below "
        "this number; unset = every seed, 0 = none (a run's steps take about 200 kB) [-]",
    )
    seeds_per_task: Int | None = Field(
        None,
        ge=1,
        le=MAX_SEEDS_PER_TASK_SETTING,
        description="campaigns: seeds run together as one task (all architectures), written "
        "to one file per architecture and journaled at once; larger means fewer files and "
        "faster campaigns, smaller a finer resume and progress; unset = at least 4 tasks per "
        "worker, at most 16 seeds a task; never changes the numbers [-]",
    )
    rrd_seeds: Int | None = Field(
        3,
        ge=0,
        le=MAX_SEED,
        description="campaigns: write a Rerun recording (all architectures of a seed and the "
        "references, about 1.6 MB for four architectures) for seeds below this number at "
        "each grid point; 0 = none, unset = every seed [-]",
    )
    design_steps_points: Int = Field(
        1,
        ge=0,
        le=MAX_RUNS,
        description="sweep --design: write per-step data (steps/ dataset) and recordings only "
        "for the first this many design points, in design order (design.parquet's rows; "
        "steps_seeds and rrd_seeds apply within them); 0 = none, the design's point count or "
        "more = every point; a grid sweep writes every point [-]",
    )
    run_timeout_s: Float | None = Field(
        None,
        gt=0,
        le=MAX_RUN_TIMEOUT_S,
        description="campaigns: wall-time limit of one run, at most 86,400 (a day) [s]; a run "
        "past it is recorded "
        "failed 'timed out' and the campaign goes on; the open-loop references of a grid "
        "point get the same limit; unset = 10 s + 3 x 100 µs x steps x re-solves / 2, "
        "120 s more for a process's first run of an architecture (19.5 s for the paper's "
        "800 steps and 79 re-solves)",
    )
    dask_no_worker_timeout_s: Float = Field(
        60.0,
        gt=0,
        le=MAX_RUN_TIMEOUT_S,
        description="campaigns on Dask (--executor dask): how long the cluster may have no "
        "worker at all before the campaign stops with exit 3 (resumable; its journaled runs "
        "kept), at most 86,400 [s]",
    )

    @field_validator("dir")
    @classmethod
    def _plain_dir(cls, value: str) -> str:
        if "\x00" in value:
            raise ValueError("must not contain a NUL character")
        return value

    @field_validator("name")
    @classmethod
    def _safe_name(cls, value: str | None) -> str | None:
        if value is None:
            return None
        if len(value) > 128 or not _SAFE_NAME.fullmatch(value):
            raise ValueError(
                "must be a plain name: letters, digits, '.', '_', '-', starting with a "
                "letter or digit, no path separators, at most 128 characters"
            )
        return value


#: A semi-axis of the keep-out ellipsoid [km]: positive, within the position bound.
SemiAxisKm = Annotated[float, Strict(), Field(gt=0, le=POSITION_MAX_KM)]
#: An entry of the corridor axis [-] (normalised at use; bounded so its norm is finite).
AxisEntry = Annotated[float, Strict(), Field(ge=-GAIN_MAX, le=GAIN_MAX)]
#: Largest covariance margin k [σ]: a margin of 100 σ is already absurd.
SIGMA_MARGIN_MAX = 100.0
#: Longest abort-safety drift [s]: one day, about 15 low orbits (the program's rows and the
#: truth's check grow with it: a drift sample every 10 s of it for every node).
ABORT_SAFE_MAX_S = 86_400.0


#: Most extra keep-out bodies (``[[constraints.keep_out.bodies]]``) [-]: a bus and its
#: appendages; every body adds one row per node to the constrained program.
KEEP_OUT_BODIES_MAX = 16


class KeepOutBodyConfig(_FrozenModel):
    """One more keep-out ellipsoid (issue 34; ``[[constraints.keep_out.bodies]]``).

    Axis-aligned in the target's body frame (the relative frame for a fixed
    target), centred at ``centre_km``: ``Σ ((r_i − c_i)/a_i)² < 1``.
    """

    centre_km: tuple[PositionKm, PositionKm, PositionKm] = Field(
        description="centre c of the ellipsoid in the target's body frame (the relative frame "
        "for a fixed target); each within ±1e4 km [km]",
    )
    semi_axes_km: tuple[SemiAxisKm, SemiAxisKm, SemiAxisKm] = Field(
        description="semi-axes (a, b, c) along the body axes x, y, z; each in (0, 1e4] [km]",
    )

    @field_validator("centre_km", "semi_axes_km", mode="before")
    @classmethod
    def _three_entries(cls, value: Any) -> Any:
        return _check_length(value, 3)


class KeepOutConfig(_FrozenModel):
    """The keep-out zone (issue 32; ``[constraints.keep_out]``): an ellipsoid centred on the
    target, and optionally more ellipsoids (issue 34: a bus and its panels).

    For a tumbling target (``[target]``) every axis is a body axis and the zone
    turns with the body. Without ``bodies`` the section is written as before, so
    the hashes of existing configs do not change.
    """

    semi_axes_km: tuple[SemiAxisKm, SemiAxisKm, SemiAxisKm] = Field(
        description="semi-axes (a, b, c) of the ellipsoid (x/a)² + (y/b)² + (z/c)² < 1 along x "
        "radial, y along-track, z cross-track (the body axes of a tumbling target); each in "
        "(0, 1e4] [km]",
    )
    bodies: tuple[KeepOutBodyConfig, ...] = Field(
        (),
        max_length=KEEP_OUT_BODIES_MAX,
        description="more keep-out ellipsoids, each a [[constraints.keep_out.bodies]] table "
        "with centre_km and semi_axes_km in the body frame; the zone is their union with the "
        "one above; at most 16 [-]",
    )

    @field_validator("semi_axes_km", mode="before")
    @classmethod
    def _three_axes(cls, value: Any) -> Any:
        return _check_length(value, 3)

    @model_serializer(mode="wrap")
    def _without_empty_bodies(self, handler: SerializerFunctionWrapHandler) -> dict[str, Any]:
        # no extra body: written as before issue 34 (same config and campaign hashes)
        out: dict[str, Any] = handler(self)
        if not self.bodies:
            out.pop("bodies", None)
        return out

    def ellipsoids(self) -> list[tuple[tuple[float, float, float], tuple[float, float, float]]]:
        """``(centre_km, semi_axes_km)`` of every ellipsoid, the centred one first."""
        return [((0.0, 0.0, 0.0), self.semi_axes_km)] + [
            (b.centre_km, b.semi_axes_km) for b in self.bodies
        ]

    def levels(self, point_km: Sequence[float]) -> list[float]:
        """``(x/a)² + (y/b)² + (z/c)²`` of ``point_km`` in each ellipsoid of :meth:`ellipsoids`
        (relative to its centre; < 1: inside it)."""
        return [
            sum(((p - c) / a) ** 2 for p, c, a in zip(point_km, centre, axes, strict=True))
            for centre, axes in self.ellipsoids()
        ]


class CorridorConfig(_FrozenModel):
    """An approach corridor: a cone with apex at the docking port (``[constraints.corridor]``).

    Inside the cone the keep-out zone is waived. With a corridor, ``scenario.xf``
    is the port at rest: unset, it is set to ``[port_km, 0, 0, 0]``; set to
    anything else, the config is refused.
    """

    port_km: tuple[PositionKm, PositionKm, PositionKm] = Field(
        description="docking port p (the cone's apex and the terminal position), on or outside "
        "the keep-out surface; each within ±1e4 km [km]",
    )
    axis: tuple[AxisEntry, AxisEntry, AxisEntry] = Field(
        description="outward corridor axis (from the port away from the target), any non-zero "
        "length (normalised by the tool); each entry in [-1e6, 1e6] [-]",
    )
    half_angle_deg: Float = Field(gt=0, lt=90, description="cone half-angle θ, in (0, 90) [deg]")

    @field_validator("port_km", "axis", mode="before")
    @classmethod
    def _three_entries(cls, value: Any) -> Any:
        return _check_length(value, 3)

    @field_validator("axis")
    @classmethod
    def _non_zero(cls, value: tuple[float, float, float]) -> tuple[float, float, float]:
        if not any(value):
            raise ValueError("must be a non-zero vector")
        return value


class ConstraintsConfig(_FrozenModel):
    """Path constraints (issue 32; ``[constraints]``); none by default.

    A position is safe when it is outside the keep-out zone or inside the
    corridor. Measured on the true trajectory of every run; enforced by the
    cone-program (``socp``) guidance only: the shooting method stays
    unconstrained. Off (no keep-out zone, no corridor, no margin), the section is
    left out of the resolved config, so the config hash and every number are as
    without it.
    """

    keep_out: KeepOutConfig | None = Field(
        None, description="keep-out ellipsoid centred on the target (unset: none)"
    )
    corridor: CorridorConfig | None = Field(
        None, description="approach corridor with apex at the port (unset: none)"
    )
    sigma_margin: Float = Field(
        0.0,
        ge=0,
        le=SIGMA_MARGIN_MAX,
        description="covariance margin k: constraints tightened by k·√(nᵀ P_pos n) along their "
        "normal n, in [0, 100] [-]",
    )

    enforce: Annotated[bool, Strict()] = Field(
        True,
        description="true: the cone-program (socp) guidance plans with the keep-out zone and "
        "the corridor; false: measure only, the guidance plans as without [constraints] (the "
        "same terminal state) while every run is measured against them as with true [-]",
    )
    abort_safe_s: Float | None = Field(
        None,
        gt=0,
        le=ABORT_SAFE_MAX_S,
        description="abort (passive) safety: the free drift from every node of the socp plan "
        "stays outside the keep-out zone (every body, turning with a tumbling target) for "
        "this long (the final approach in the corridor exempt), in (0, 86400]; unset: off [s]",
    )

    @model_serializer(mode="wrap")
    def _without_unset(self, handler: SerializerFunctionWrapHandler) -> dict[str, Any]:
        # an unset zone or corridor is left out (TOML has no null; a dotted key can then
        # create it: --set constraints.corridor.half_angle_deg=…)
        out: dict[str, Any] = handler(self)
        if self.enforce:
            out.pop("enforce", None)  # the default: written as before (same hashes)
        return {k: v for k, v in out.items() if v is not None}

    @model_validator(mode="after")
    def _measure_only_rules(self) -> Self:
        # enforce = false: nothing the guidance would use may be set (it would do nothing)
        if self.enforce:
            return self
        if self.keep_out is None:
            raise rules_error(
                [
                    (
                        "enforce",
                        False,
                        "measure-only needs a keep-out zone to measure against (without one "
                        "nothing is enforced either): set constraints.keep_out.semi_axes_km, "
                        "or leave enforce out",
                    )
                ]
            )
        if self.sigma_margin != 0.0:
            raise rules_error(
                [
                    (
                        "sigma_margin",
                        self.sigma_margin,
                        "with constraints.enforce = false the guidance plans without the "
                        "constraints, so the margin would do nothing: leave it 0, or set "
                        "enforce = true",
                    )
                ]
            )
        return self

    @model_validator(mode="after")
    def _abort_needs_a_zone(self) -> Self:
        if self.abort_safe_s is not None and self.keep_out is None:
            raise rules_error(
                [
                    (
                        "abort_safe_s",
                        self.abort_safe_s,
                        "abort safety keeps the free drift out of the keep-out zone: set "
                        "constraints.keep_out.semi_axes_km, or leave abort_safe_s out",
                    )
                ]
            )
        return self

    @model_validator(mode="after")
    def _corridor_points_away(self) -> Self:
        # an axis into the target: the cone holds the target's centre (the centred
        # ellipsoid's) and would waive the zone's core (other bodies the corridor may cross)
        corridor = self.corridor
        if self.keep_out is None or corridor is None:
            return self
        w = [-p for p in corridor.port_km]  # from the port to the target's centre
        length = math.sqrt(sum(v * v for v in w))
        norm = math.sqrt(sum(a * a for a in corridor.axis))
        along = sum(a * v for a, v in zip(corridor.axis, w, strict=True)) / norm
        if length == 0.0 or along < math.cos(math.radians(corridor.half_angle_deg)) * length:
            return self
        raise rules_error(
            [
                (
                    "corridor.axis",
                    list(corridor.axis),
                    "the corridor holds the target's centre, so it would waive the keep-out "
                    "zone's core: the axis points outward, from the port away from the target "
                    f"(e.g. [{', '.join(fmt_num(-a) for a in corridor.axis)}])",
                )
            ]
        )

    @model_validator(mode="after")
    def _port_outside_keep_out(self) -> Self:
        if self.keep_out is not None and self.corridor is not None:
            for i, level in enumerate(self.keep_out.levels(self.corridor.port_km)):
                if level >= 1.0 - PORT_SURFACE_TOL:
                    continue
                where = (
                    "(x/a)² + (y/b)² + (z/c)² = "
                    f"{level:.6g} < 1 with (a, b, c) = keep_out.semi_axes_km"
                    if i == 0
                    else f"it is inside keep_out.bodies.{i - 1} (level {level:.6g} < 1)"
                )
                raise rules_error(
                    [
                        (
                            "corridor.port_km",
                            list(self.corridor.port_km),
                            f"must lie on or outside the keep-out zone: {where}",
                        )
                    ]
                )
        return self

    @property
    def active(self) -> bool:
        """True when a keep-out zone or a corridor is configured."""
        return self.keep_out is not None or self.corridor is not None


#: Relative tolerance of "on the keep-out surface" for the port [-]: a port computed as a
#: point of the surface (a·û) may land a few ulps inside.
PORT_SURFACE_TOL = 1e-12


#: A component of the initial attitude quaternion [-] (normalised at use; bounded so its
#: norm is finite).
QuaternionEntry = Annotated[float, Strict(), Field(ge=-GAIN_MAX, le=GAIN_MAX)]
#: Largest body rate about one axis [deg/s]: 10 rpm, six times the fastest tumble of the
#: public reference study of issue 34 (10 °/s, Sow et al. 2024).
BODY_RATE_MAX_DEG_S = 60.0
BodyRateDegS = Annotated[float, Strict(), Field(ge=-BODY_RATE_MAX_DEG_S, le=BODY_RATE_MAX_DEG_S)]
#: A principal moment of inertia as a ratio [-]: positive, at most 1e6 (only ratios matter).
InertiaRatio = Annotated[float, Strict(), Field(gt=0, le=GAIN_MAX)]


#: Largest attitude-knowledge error σ [deg]: beyond 30° per axis the prediction is noise.
KNOWLEDGE_SIGMA_MAX_DEG = 30.0


class TargetConfig(_FrozenModel):
    """The target's attitude (issue 34; ``[target]``); ``fixed`` by default.

    ``fixed``: the target's body axes stay along the relative frame (x radial,
    y along-track, z cross-track), today's geometry. ``tumbling``: a torque-free
    rigid body (:mod:`cwrend_cli.physics.attitude`). The tumbling fields are
    refused with ``fixed`` (they would do nothing). Fixed, the section is left out
    of the resolved config, so the config hash and every number are as without
    it. With a tumbling target the keep-out ellipsoids, the port and the corridor
    axis of ``[constraints]`` are given in the target's body frame and turn with it.
    """

    attitude: Literal["fixed", "tumbling"] = Field(
        "fixed",
        description="'fixed' (body axes along the relative frame) or 'tumbling' (torque-free "
        "rigid body) [-]",
    )
    initial_quaternion: tuple[
        QuaternionEntry, QuaternionEntry, QuaternionEntry, QuaternionEntry
    ] = Field(
        (1.0, 0.0, 0.0, 0.0),
        description="tumbling: attitude at t = 0, body to relative frame, scalar-first "
        "(q0, q1, q2, q3), any non-zero length (normalised by the tool); each entry in "
        "[-1e6, 1e6] [-]",
    )
    body_rates_deg_s: tuple[BodyRateDegS, BodyRateDegS, BodyRateDegS] = Field(
        (0.0, 0.0, 0.0),
        description="tumbling: angular velocity at t = 0 relative to inertial space, in body "
        "axes (with its z axis along the orbit normal, a target at rest in the relative frame "
        "has [0, 0, n]); each in [-60, 60] [deg/s]",
    )
    inertia: tuple[InertiaRatio, InertiaRatio, InertiaRatio] = Field(
        (1.0, 1.0, 1.0),
        description="tumbling: principal moments of inertia (I1, I2, I3) about the body axes, "
        "as ratios; each in (0, 1e6], no one above the sum of the other two [-]",
    )

    knowledge_sigma_deg: Float = Field(
        0.0,
        ge=0,
        le=KNOWLEDGE_SIGMA_MAX_DEG,
        description="tumbling: the constrained guidance's attitude-knowledge error, σ of a "
        "rotation about each body axis drawn once a run from its own stream; in [0, 30] [deg]",
    )
    knowledge_sigma_deg_s: Float = Field(
        0.0,
        ge=0,
        le=BODY_RATE_MAX_DEG_S,
        description="tumbling: the constrained guidance's body-rate knowledge error, σ per "
        "axis drawn once a run from its own stream; in [0, 60] [deg/s]",
    )
    knowledge_draw: Literal["run", "resolve"] = Field(
        "run",
        description="tumbling, with a knowledge error: 'run' draws the error once a run (the "
        "same at every re-solve), 'resolve' afresh at every re-solve (independent draws of "
        "the same σ, from the run's own stream) [-]",
    )

    @model_serializer(mode="wrap")
    def _without_perfect_knowledge(self, handler: SerializerFunctionWrapHandler) -> Any:
        # perfect attitude knowledge (the default) is written as before the fields existed
        out: dict[str, Any] = handler(self)
        for name in ("knowledge_sigma_deg", "knowledge_sigma_deg_s"):
            if getattr(self, name) == 0.0:
                out.pop(name, None)
        if self.knowledge_draw == "run":
            out.pop("knowledge_draw", None)
        return out

    @field_validator("initial_quaternion", "body_rates_deg_s", "inertia", mode="before")
    @classmethod
    def _lengths(cls, value: Any, info: ValidationInfo) -> Any:
        return _check_length(value, 4 if info.field_name == "initial_quaternion" else 3)

    @field_validator("initial_quaternion")
    @classmethod
    def _non_zero(cls, value: tuple[float, ...]) -> tuple[float, ...]:
        if not any(value):
            raise ValueError("must be a non-zero quaternion (e.g. [1, 0, 0, 0])")
        return value

    @field_validator("inertia")
    @classmethod
    def _triangle(cls, value: tuple[float, float, float]) -> tuple[float, float, float]:
        # a rigid body's principal moments obey I_i <= I_j + I_k (each is a sum of two of
        # the three second moments of its mass distribution)
        for i in range(3):
            others = value[(i + 1) % 3] + value[(i + 2) % 3]
            if value[i] > others:
                raise ValueError(
                    f"no rigid body has these moments: I{i + 1} = {fmt_num(value[i])} exceeds "
                    f"the sum of the other two ({fmt_num(others)}): each must be at most the "
                    "sum of the other two"
                )
        return value

    @model_validator(mode="after")
    def _tumbling_fields_only_when_tumbling(self) -> Self:
        if self.attitude == "fixed":
            unused = [
                (name, getattr(self, name))
                for name in (
                    "initial_quaternion",
                    "body_rates_deg_s",
                    "inertia",
                    "knowledge_sigma_deg",
                    "knowledge_sigma_deg_s",
                    "knowledge_draw",
                )
                if getattr(self, name) != type(self).model_fields[name].default
            ]
            if unused:
                name, value = unused[0]
                raise rules_error(
                    [
                        (
                            name,
                            list(value) if isinstance(value, tuple) else value,
                            "applies to a tumbling target only: set target.attitude = "
                            "'tumbling', or leave it out",
                        )
                    ]
                )
        if (
            self.knowledge_draw != "run"
            and self.knowledge_sigma_deg == 0.0
            and self.knowledge_sigma_deg_s == 0.0
        ):
            raise rules_error(
                [
                    (
                        "knowledge_draw",
                        self.knowledge_draw,
                        "there is no knowledge error to draw: set target.knowledge_sigma_deg "
                        "or target.knowledge_sigma_deg_s above 0, or leave it out",
                    )
                ]
            )
        return self


SweepValue = Float | Int | bool | str | tuple[Float, ...]


class Dispersion(_FrozenModel):
    """A per-run random draw applied to one config value (``[dispersions]`` table).

    ``normal``: ``mean + std·z``; ``uniform``: ``U(low, high)``. With
    ``mode = "add"`` (default) the draw is added to the base value, with
    ``"set"`` it replaces it. Draws come from the run's own random stream,
    keyed by (noise.seed, seed), so every architecture of a seed flies the
    same dispersed scenario.
    """

    dist: Literal["normal", "uniform"] = Field(description="distribution of the draw [-]")
    # each within ±DISPERSION_MAX, the largest bound of any value a draw may set (a
    # position variance); the dispersed run is then validated like any configuration
    mean: DispersionValue = Field(
        0.0,
        description="normal: mean of the draw, within ±1e8 [the key's unit]",
    )
    std: Float | None = Field(
        None,
        ge=0,
        le=DISPERSION_MAX,
        description="normal: standard deviation, in [0, 1e8] [the key's unit]",
    )
    low: DispersionValue | None = Field(
        None,
        description="uniform: lower bound, within ±1e8 [the key's unit]",
    )
    high: DispersionValue | None = Field(
        None,
        description="uniform: upper bound, within ±1e8 [the key's unit]",
    )
    mode: Literal["add", "set"] = Field("add", description="add the draw to the base or set it [-]")

    @model_validator(mode="after")
    def _parameters_present(self) -> Self:
        if self.dist == "normal" and self.std is None:
            raise rules_error([("std", None, "required for dist = 'normal'")])
        if self.dist == "uniform":
            if self.low is None or self.high is None:
                raise rules_error([("low", None, "low and high required for dist = 'uniform'")])
            if self.high < self.low:
                raise rules_error([("high", self.high, f"must be >= low ({self.low})")])
        return self


class CwrendConfig(_FrozenModel):
    """The whole configuration of a cwrend run or campaign (defaults: docs/method.md).

    ``sweep`` and ``dispersions`` describe campaigns (``cwrend sweep``); a
    single run ignores them.
    """

    scenario: ScenarioConfig = Field(default_factory=ScenarioConfig, description="scenario")
    estimator: EstimatorConfig = Field(default_factory=EstimatorConfig, description="Kalman filter")
    schedule: ScheduleConfig = Field(
        default_factory=ScheduleConfig, description="adaptive homotopy schedule"
    )
    guidance: GuidanceConfig = Field(
        default_factory=GuidanceConfig, description="receding-horizon guidance"
    )
    solver: SolverConfig = Field(default_factory=SolverConfig, description="shooting solver")
    degradation: DegradationConfig = Field(
        default_factory=DegradationConfig, description="sensor degradation windows"
    )
    truth: TruthConfig = Field(
        default_factory=TruthConfig,
        description="truth dynamics (guidance and filter: CW unless [model])",
    )
    actuator: ActuatorConfig = Field(
        default_factory=ActuatorConfig, description="actuator errors (the truth gets them)"
    )
    constraints: ConstraintsConfig = Field(
        default_factory=ConstraintsConfig,
        description="path constraints: keep-out zone, corridor (socp guidance; measured always)",
    )
    model: ModelConfig = Field(
        default_factory=ModelConfig,
        description="design models of the guidance and the filter (default CW)",
    )
    sensor: SensorConfig = Field(
        default_factory=SensorConfig,
        description="what the chaser measures: position (default), range_bearing or angles",
    )
    target: TargetConfig = Field(
        default_factory=TargetConfig,
        description="the target's attitude: fixed (default) or tumbling",
    )
    noise: NoiseConfig = Field(default_factory=NoiseConfig, description="measurement noise")
    output: OutputConfig = Field(default_factory=OutputConfig, description="output location")
    sweep: dict[str, tuple[SweepValue, ...] | str | dict[str, Any]] = Field(
        default_factory=dict,
        max_length=MAX_SWEPT_KEYS,
        description="grid: dotted.key = [v1, v2, …] or 'start:stop:num' (cartesian product); "
        "or, for cwrend sweep --design, ranges: dotted.key = { low = …, high = … } "
        "(log = true, int = true) or { values = […] }; at most 1,000 keys [the key's unit]",
    )
    dispersions: dict[str, Dispersion] = Field(
        default_factory=dict,
        max_length=MAX_SWEPT_KEYS,
        description="per-run random draws: dotted.key = {dist = …}; at most 1,000 keys",
    )

    @field_validator("sweep", mode="before")
    @classmethod
    def _no_table_values(cls, value: Any) -> Any:
        # a list of tables: one clear refusal, not one per branch of the value's union
        if isinstance(value, dict):
            for key, values in value.items():
                tables = (
                    [v for v in values if isinstance(v, dict)] if isinstance(values, list) else []
                )
                if tables:
                    raise rules_error(
                        [(str(key), values, table_value_problem(str(key), tables[0]))]
                    )
        return value

    @model_validator(mode="before")
    @classmethod
    def _xf_at_the_port(cls, data: Any) -> Any:
        # With a corridor and no scenario.xf, the terminal state is the port at rest
        # (issue 32); an explicit xf is checked against it by _cross_section_rules.
        if not isinstance(data, dict):
            return data
        constraints = data.get("constraints")
        corridor = (
            constraints.get("corridor")
            if isinstance(constraints, dict)
            else getattr(constraints, "corridor", None)
        )
        port = (
            corridor.get("port_km")
            if isinstance(corridor, dict)
            else getattr(corridor, "port_km", None)
        )
        if not isinstance(port, (list, tuple)) or len(port) != 3:
            return data  # no corridor, or a malformed port its own validator names
        scenario = data.get("scenario", {})
        if isinstance(scenario, ScenarioConfig):
            if "xf" in scenario.model_fields_set:
                return data
            return {**data, "scenario": scenario.model_copy(update={"xf": (*port, 0, 0, 0)})}
        if isinstance(scenario, dict) and "xf" not in scenario:
            return {**data, "scenario": {**scenario, "xf": [*port, 0.0, 0.0, 0.0]}}
        return data

    @model_serializer(mode="wrap")
    def _without_constraints_when_off(self, handler: SerializerFunctionWrapHandler) -> Any:
        # no [constraints]: left out of the resolved tree, which the config and campaign
        # hashes are computed from, so every existing hash (and number) is unchanged
        out = handler(self)
        if isinstance(out, dict) and self.constraints == ConstraintsConfig():
            out.pop("constraints", None)
        if isinstance(out, dict) and self.model == ModelConfig():
            out.pop("model", None)  # no [model]: CW, hashes unchanged (issue 33)
        if isinstance(out, dict) and self.target == TargetConfig():
            out.pop("target", None)  # a fixed target: hashes unchanged (issue 34)
        if isinstance(out, dict) and self.sensor == SensorConfig():
            out.pop("sensor", None)  # no [sensor]: position, hashes unchanged (issue 35)
        return out

    @model_validator(mode="after")
    def _nis_offset_of_the_sensor(self) -> Self:
        # schedule.nis_offset is the measurement dimension m of paper Eq. 24: unless given,
        # 2 for the angles sensor (issue 35); 3 (the default) for the others. A filled-in
        # value stays out of the schedule's fields set: a point of a sweep over sensor.model
        # tells it from one the user gave (campaign.plan, nis_offset_given)
        if self.sensor.model == "angles" and not nis_offset_given(self):
            schedule = self.schedule.model_copy(update={"nis_offset": 2.0})
            schedule.__pydantic_fields_set__.discard("nis_offset")
            object.__setattr__(self, "schedule", schedule)  # frozen: set once, while validated
        return self

    @model_validator(mode="after")
    def _sensor_rules(self) -> Self:
        problems = sensor_problems(self)
        if problems:
            raise rules_error(problems)
        return self

    @model_validator(mode="after")
    def _design_model_rules(self) -> Self:
        problems: list[tuple[str, Any, str]] = []
        for consumer in ("guidance", "filter"):
            name = getattr(self.model, consumer)
            if name != "cw" and self.truth.model == "cw":
                problems.append(
                    (
                        f"model.{consumer}",
                        name,
                        f"'{name}' takes the chief's orbit from [truth], which the 'cw' truth "
                        "does not fly: set truth.model = 'two_body' or 'j2' (with the chief's "
                        "elements), or use 'cw'",
                    )
                )
        if self.truth.model == "cw" and self.truth.eccentricity != 0.0:
            problems.append(
                (
                    "truth.eccentricity",
                    self.truth.eccentricity,
                    "the 'cw' truth (truth.model) flies a circular chief and ignores it: set "
                    "truth.model = 'two_body' or 'j2' to fly an eccentric chief, or leave it 0",
                )
            )
        if problems:
            raise rules_error(problems)
        return self

    @model_validator(mode="after")
    def _cross_section_rules(self) -> Self:
        sc = self.scenario
        problems: list[tuple[str, Any, str]] = []
        for i, w in enumerate(self.degradation.windows):
            if w.end_s > sc.horizon_s:
                problems.append(
                    (
                        f"degradation.windows.{i}.end_s",
                        w.end_s,
                        f"window must lie within [0, scenario.horizon_s] = "
                        f"[0, {fmt_num(sc.horizon_s)}]",
                    )
                )
        if not _is_whole_multiple(self.guidance.t_resolve_s, sc.dt_s):
            problems.append(
                (
                    "guidance.t_resolve_s",
                    self.guidance.t_resolve_s,
                    f"must be a whole multiple of scenario.dt_s ({fmt_num(sc.dt_s)})",
                )
            )
        if self.truth.model != "cw":
            # here, not at the top: physics.truth loads numba and scipy (about 1.5 s), which
            # `cwrend config validate` and `--help` do not need (issue 17)
            from cwrend_cli.physics.truth import R_EARTH_KM, semi_major_axis_km

            perigee = semi_major_axis_km(sc.mean_motion_rad_s) * (1.0 - self.truth.eccentricity)
            if perigee <= R_EARTH_KM:
                problems.append(
                    (
                        "truth.eccentricity",
                        self.truth.eccentricity,
                        f"the chief's perigee radius a(1 - e) = {perigee:.1f} km "
                        f"(a from scenario.mean_motion_rad_s) must exceed Earth's radius "
                        f"({fmt_num(R_EARTH_KM)} km)",
                    )
                )
        act = self.actuator
        if act.delay_steps >= sc.n_steps:
            problems.append(
                (
                    "actuator.delay_steps",
                    act.delay_steps,
                    f"must be < the number of steps ({sc.n_steps})",
                )
            )
        if act.min_thrust_km_s2 > sc.u_max_km_s2:
            problems.append(
                (
                    "actuator.min_thrust_km_s2",
                    act.min_thrust_km_s2,
                    f"must be <= scenario.u_max_km_s2 ({fmt_num(sc.u_max_km_s2)})",
                )
            )
        if (
            self.target.attitude == "tumbling"
            and self.constraints.corridor is not None
            and self.constraints.keep_out is None
        ):
            problems.append(
                (
                    "constraints.corridor",
                    "set",
                    "a tumbling target's moving port is flown to by the constrained cone "
                    "program, which needs a keep-out zone: add [constraints.keep_out] or "
                    "leave out the corridor",
                )
            )
        for name in ("knowledge_sigma_deg", "knowledge_sigma_deg_s"):
            if getattr(self.target, name) > 0.0 and self.constraints.keep_out is None:
                problems.append(
                    (
                        f"target.{name}",
                        getattr(self.target, name),
                        "the attitude knowledge is used by the constrained guidance only, "
                        "which needs a keep-out zone: add [constraints.keep_out] or leave it 0",
                    )
                )
            elif getattr(self.target, name) > 0.0 and not self.constraints.enforce:
                problems.append(
                    (
                        f"target.{name}",
                        getattr(self.target, name),
                        "the attitude knowledge is used by the constrained guidance only, "
                        "which constraints.enforce = false turns off: leave it 0, or set "
                        "enforce = true",
                    )
                )
        start = start_in_keep_out(self)
        if start is not None:
            problems.append(("scenario.x0", list(sc.x0), start))
        corridor = self.constraints.corridor
        if corridor is not None and tuple(sc.xf) != (*corridor.port_km, 0.0, 0.0, 0.0):
            problems.append(
                (
                    "scenario.xf",
                    list(sc.xf),
                    "with a corridor the terminal state is the port at rest, "
                    f"[{', '.join(fmt_num(p) for p in corridor.port_km)}, 0, 0, 0] "
                    "(constraints.corridor.port_km): leave scenario.xf unset or set it so",
                )
            )
        if self.guidance.t_min_rem_s >= sc.horizon_s:
            problems.append(
                (
                    "guidance.t_min_rem_s",
                    self.guidance.t_min_rem_s,
                    f"must be < scenario.horizon_s ({fmt_num(sc.horizon_s)})",
                )
            )
        noise_problem = _noise_file_too_large(self.noise.file, sc.n_steps)
        if noise_problem is not None:
            problems.append(("noise.file", self.noise.file, noise_problem))
        if problems:
            raise rules_error(problems)
        return self


def start_in_keep_out(cfg: CwrendConfig) -> str | None:
    """Why the start position of ``scenario.x0`` is unsafe at t = 0, or ``None`` when it is safe.

    Unsafe: inside the keep-out zone (any of its ellipsoids) and outside the corridor,
    i.e. the signed distance φ of :func:`cwrend_cli.physics.constraints.signed_distance`
    is negative. For a tumbling target the position is taken into the body frame at
    the attitude of t = 0 (``target.initial_quaternion``, body → relative frame).
    """
    if cfg.constraints.keep_out is None:
        return None  # without a zone nothing is unsafe
    # here, not at the top: numpy, which `cwrend config validate` of most configs does not need
    import numpy as np

    from cwrend_cli.config.adapt import constraints_of
    from cwrend_cli.physics.constraints import (
        ellipsoid_level,
        ellipsoids,
        geometry,
        rotation_matrices,
        signed_distance,
    )

    constraints = constraints_of(cfg)
    assert constraints is not None  # a keep-out zone is set
    geo = geometry(constraints)
    r = np.asarray(cfg.scenario.x0[:3], dtype=np.float64)
    frame = ""
    if cfg.target.attitude == "tumbling":
        q = np.asarray(cfg.target.initial_quaternion, dtype=np.float64)
        r = rotation_matrices(q / np.linalg.norm(q)).T @ r  # relative → body frame
        frame = " (in the body frame at t = 0, target.initial_quaternion)"
    if float(signed_distance(r, geo)) >= 0.0:
        return None
    (inside, *_) = [
        "constraints.keep_out.semi_axes_km" if i == 0 else f"constraints.keep_out.bodies.{i - 1}"
        for i, (centre, axes) in enumerate(ellipsoids(geo))
        if float(ellipsoid_level(r if centre is None else r - centre, axes)) < 1.0
    ]
    outside = "" if constraints.corridor is None else " and outside the corridor"
    into = "" if constraints.corridor is None else " (or inside the corridor)"
    return (
        f"the start position [{', '.join(fmt_num(float(v)) for v in cfg.scenario.x0[:3])}] km "
        f"is inside the keep-out zone{outside}{frame}, in the ellipsoid {inside}: start "
        f"outside the zone{into}, or change {inside}"
    )


def end_in_keep_out(cfg: CwrendConfig) -> str | None:
    """Why the terminal position of ``scenario.xf`` lies in the keep-out zone (no corridor:
    then no safe plan can end there), or ``None`` when it does not. Checked where a
    cone-program architecture would plan with the constraints
    (:func:`cwrend_cli.campaign.plan.check_terminal_state`): a shooting run or a
    measure-only config may end there, measured.

    A fixed target: inside any ellipsoid of the zone. A tumbling target, whose zone has an
    attitude at T that validation does not propagate: within the centred ellipsoid's
    smallest semi-axis of the centre, inside it whatever the attitude.
    """
    keep_out = cfg.constraints.keep_out
    if keep_out is None or cfg.constraints.corridor is not None:
        return None
    r = cfg.scenario.xf[:3]
    if cfg.target.attitude == "tumbling":  # the centred ellipsoid's inscribed ball
        inside = [0] if sum(v * v for v in r) < min(keep_out.semi_axes_km) ** 2 else []
    else:
        inside = [i for i, level in enumerate(keep_out.levels(r)) if level < 1.0]
    where = [
        "constraints.keep_out.semi_axes_km" if i == 0 else f"constraints.keep_out.bodies.{i - 1}"
        for i in inside
    ]
    if not where:
        return None
    return (
        f"the terminal position [{', '.join(fmt_num(float(v)) for v in r)}] km is inside the "
        f"keep-out zone, in the ellipsoid {where[0]}: no safe plan can end there; add a "
        "[constraints.corridor] (its port, on the zone's surface or outside it, is then the "
        "terminal state), set scenario.xf outside the zone, or change " + where[0]
    )


def _noise_file_too_large(file: str | None, n_steps: int) -> str | None:
    """Why ``file`` is too large to be a noise file of ``n_steps`` rows, or ``None``.

    The bound is :func:`cwrend_cli.limits.noise_file_max_bytes` (about 1 kB a step
    plus 1 MiB): checked on the file's size alone, before anything hashes or reads
    it (issue 36 item 9).
    """
    if file is None:
        return None
    try:
        size = Path(file).stat().st_size
    except OSError:
        return None  # reading it reports the problem
    return noise_file_too_large(size, n_steps)


def nis_offset_given(cfg: CwrendConfig) -> bool:
    """Whether ``schedule.nis_offset`` was given (in the file, ``--set`` or a swept value).

    Not given: the measurement dimension m of the sensor fills it in (3, or 2 for angles).
    """
    return "nis_offset" in cfg.schedule.model_fields_set


def xf_given(cfg: CwrendConfig) -> bool:
    """Whether ``scenario.xf`` was given (in the file, ``--set`` or a swept value).

    Not given: the built-in terminal state. Asked of a base without a corridor
    (:func:`~cwrend_cli.config.overrides.point_tree`): with one, validation fills
    the port at rest in, which then counts as given.
    """
    return "xf" in cfg.scenario.model_fields_set


def sensor_problems(cfg: CwrendConfig) -> list[tuple[str, Any, str]]:
    """The fields of ``cfg`` that make no sense with its sensor model (issue 35), with the fix."""
    model = cfg.sensor.model
    default = SensorConfig()
    problems: list[tuple[str, Any, str]] = []
    unused: list[str] = []
    if model == "position":
        unused = ["sigma_range_km", "sigma_range_fraction", "sigma_angle_deg"]
    elif model == "angles":
        unused = ["sigma_range_km", "sigma_range_fraction"]
    for name in unused:
        value = getattr(cfg.sensor, name)
        if value != getattr(default, name):
            problems.append(
                (
                    f"sensor.{name}",
                    value,
                    f"the '{model}' sensor measures no "
                    + ("angle" if name == "sigma_angle_deg" else "range")
                    + ": leave it unset or set sensor.model to one that does"
                    + (
                        " (estimator.r_nominal_km2 is the position sensor's noise)"
                        if model == "position"
                        else ""
                    ),
                )
            )
    if model != "position" and cfg.estimator.r_nominal_km2 != EstimatorConfig().r_nominal_km2:
        problems.append(
            (
                "estimator.r_nominal_km2",
                cfg.estimator.r_nominal_km2,
                f"the '{model}' sensor's noise is set by sensor.sigma_range_km, "
                "sigma_range_fraction and sigma_angle_deg: leave r_nominal_km2 at the default",
            )
        )
    m = 2 if model == "angles" else 3
    for i, w in enumerate(cfg.degradation.windows):
        key = f"degradation.windows.{i}"
        for name in ("r_scale", "outlier_probability", "outlier_scale"):
            value = getattr(w, name)
            if isinstance(value, tuple) and len(value) != m:
                problems.append(
                    (
                        f"{key}.{name}",
                        list(value),
                        f"must be one value or {m} (one per component of the '{model}' "
                        "sensor's measurement)",
                    )
                )
        if model != "range_bearing" and w.bias_range_km != 0.0:
            problems.append(
                (
                    f"{key}.bias_range_km",
                    w.bias_range_km,
                    f"the '{model}' sensor measures no range: use "
                    + ("bias_km" if model == "position" else "bias_angles_deg")
                    + " or sensor.model = 'range_bearing'",
                )
            )
        if model == "position" and tuple(w.bias_angles_deg) != (0.0, 0.0):
            problems.append(
                (
                    f"{key}.bias_angles_deg",
                    list(w.bias_angles_deg),
                    "the 'position' sensor measures no angle: use bias_km, or "
                    "sensor.model = 'range_bearing' or 'angles'",
                )
            )
    return problems
