"""Typed parameters of the physics core: small frozen dataclasses, no validation, no I/O.

These mirror the sections of the configuration field for field (same names,
same units), so a dotted key such as ``scenario.x0.2`` or
``degradation.windows.1.bias_km.0`` names the same value here as in a config
file. The configuration layer (:mod:`cwrend_cli.config`) validates user input
once and converts it into these types (:mod:`cwrend_cli.config.adapt`);
nothing in :mod:`cwrend_cli.physics` ever sees a pydantic model.

Units everywhere (the paper's, Table 1): km, s, km/s, km/s², rad/s; covariances in the
matching squared units.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import TYPE_CHECKING, Literal

if TYPE_CHECKING:
    import numpy as np
    import numpy.typing as npt

    #: A float64 array (shapes are given in docstrings).
    FloatArray = npt.NDArray[np.float64]
else:

    def __getattr__(name: str) -> object:
        """``FloatArray`` (``numpy.typing.NDArray[numpy.float64]``), built on first use.

        These parameters import no numpy (issue 17: ``cwrend config validate`` and the
        configuration models use them, and numpy costs about 0.1 s to import); the
        modules that compute import numpy anyway.
        """
        if name != "FloatArray":
            raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
        import numpy as np
        import numpy.typing as npt

        alias = npt.NDArray[np.float64]
        globals()["FloatArray"] = alias
        return alias


Vec3 = tuple[float, float, float]
Vec6 = tuple[float, float, float, float, float, float]
#: A covariance as stored: its n diagonal entries, or the full n×n matrix (rows).
Covariance = tuple[float, ...] | tuple[tuple[float, ...], ...]


def covariance_matrix(value: Covariance) -> FloatArray:
    """A fresh float64 matrix from a stored (diagonal or full) covariance."""
    import numpy as np

    arr = np.array(value, dtype=np.float64)
    return np.asarray(np.diag(arr) if arr.ndim == 1 else arr, dtype=np.float64)


@dataclass(frozen=True)
class Scenario:
    """Rendezvous geometry and timing (paper Eqs. 3–4, Table 1).

    x0 is given in paper Sec. "Numerical Results and Discussion". The mean motion
    is the authors' code's (a convention of cwrend; not in the paper).
    """

    mean_motion_rad_s: float = 0.00104218449  # CW mean motion n [rad/s]
    horizon_s: float = 800.0  # rendezvous horizon T [s]
    dt_s: float = 1.0  # simulation / filter / control-hold step Δt [s]
    x0: Vec6 = (0.03031809, 0.0, 31.16639, -0.02963377, 0.04570523, 0.0)  # [km, km/s]
    xf: Vec6 = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)  # target terminal state [km, km/s]
    u_max_km_s2: float = 8e-4  # maximum control acceleration [km/s²]

    @property
    def n_steps(self) -> int:
        """Number of steps N = T/Δt (the grid is t_k = k Δt, k = 0..N)."""
        return round(self.horizon_s / self.dt_s)

    def time_grid(self) -> FloatArray:
        """Grid times t_k = k Δt, k = 0 … N [s]."""
        import numpy as np

        return np.asarray(np.arange(self.n_steps + 1) * self.dt_s, dtype=np.float64)


@dataclass(frozen=True)
class Estimator:
    """Kalman filter covariances (paper Eqs. 11–21, Table 1) and initial error (cwrend's)."""

    r_nominal_km2: Covariance = (1e-6, 1e-6, 1e-6)  # nominal measurement covariance R [km²]
    q_process: Covariance = (1e-12, 1e-12, 1e-12, 1e-14, 1e-14, 1e-14)  # Q [km², km²/s²]
    p0: Covariance = (1e-6, 1e-6, 1e-6, 1e-10, 1e-10, 1e-10)  # P0 [km², km²/s²]
    initial_error: Vec6 = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)  # x̂0 − x0 [km, km/s]
    #: Q of each step (issue 33, :mod:`cwrend_cli.physics.process_noise`): ``q_process``
    #: ("fixed", the paper's), plus the actuator errors' ("from_actuator"), or the
    #: Sage–Husa estimate floored at ``q_process`` ("adaptive")
    process_noise: Literal["fixed", "from_actuator", "adaptive"] = "fixed"
    q_forgetting: float = 0.99  # forgetting factor b of the adaptive estimate, in (0, 1) [-]

    def r_nominal_matrix(self) -> FloatArray:
        """R_nominal as a new 3×3 float64 array [km²]."""
        return covariance_matrix(self.r_nominal_km2)

    def q_matrix(self) -> FloatArray:
        """Q as a new 6×6 float64 array [km², km²/s²]."""
        return covariance_matrix(self.q_process)

    def p0_matrix(self) -> FloatArray:
        """P0 as a new 6×6 float64 array [km², km²/s²]."""
        return covariance_matrix(self.p0)


@dataclass(frozen=True)
class Schedule:
    """Innovation-adaptive homotopy schedule (paper Eqs. 24–26, Table 1)."""

    beta: float = 0.25  # score-to-homotopy sensitivity β [1/score]
    nis_offset: float = 3.0  # NIS offset m [-]
    score_lowpass: float = 0.85  # low-pass coefficient ρ_s [-]
    kappa_mtf: float = 12.0  # weight κ_MTF of the MTF ratio [-]
    score_max: float = 50.0  # cap on the instantaneous score [-]
    eps_min: float = 0.0  # ε_min [-]
    eps_max: float = 1.0  # ε_max; adaptive runs start here [-]
    alpha_eps: float = 0.10  # blending factor α_ε [-]
    deadband: float = 0.0  # filtered score below which ε* = ε_min; 0 disables it [-]
    eps_saturation: float | None = None  # upper clip of ε*; None disables it [-]
    eps_fixed: float = 0.0  # ε of the fixed architectures (paper: 0, bang-bang) [-]


@dataclass(frozen=True)
class Guidance:
    """Receding-horizon re-solve settings (paper Sec. "Receding-Horizon Indirect Guidance").

    The timing and the hold are conventions of cwrend, not in the paper
    (docs/method.md). ``resolve_timing = "correct"`` solves from the estimate at t_{k+1} with
    remaining horizon T − t_{k+1}; ``"reference"`` reproduces the authors'
    code (T − t_k, then the solved costate propagated one step). ``hold``:
    the plan's control sampled at the start of each step (authors) or
    averaged over the step.
    """

    t_resolve_s: float = 10.0  # re-solve interval [s]
    t_min_rem_s: float = 20.0  # no re-solve once the remaining horizon is <= this [s]
    resolve_timing: Literal["correct", "reference"] = "correct"
    hold: Literal["sample", "mean"] = "sample"
    # re-solve method of the architectures that do not name one (issue 16): the
    # shooting solver's costate plan, or the cone program's held controls
    method: Literal["shooting", "socp"] = "shooting"


@dataclass(frozen=True)
class Solver:
    """Shooting-solver settings of a closed loop (paper Eqs. 8–10; cwrend's, not in the paper)."""

    fallback: Literal["chain", "none"] = "chain"
    on_infeasible: Literal["keep", "min_miss"] = "keep"
    success_residual: float = 1e-4  # a solve succeeds when ‖x(T) − x_f‖ is below this
    tol_pos_km: float = 1e-9  # Newton tolerance on the terminal position [km]
    tol_vel_km_s: float = 1e-12  # Newton tolerance on the terminal velocity [km/s]
    max_iter: int = 50  # Newton iterations per attempt [-]
    quadrature_nodes: int = 12  # Gauss–Legendre nodes per arc [-]
    switching_newton_steps: int = 20  # ε = 0: switching-time Newton steps first (0: ascent only)


@dataclass(frozen=True)
class Window:
    """One sensor-degradation interval, active on ``start_s ≤ t ≤ end_s`` (the paper gives
    no values: docs/method.md).

    While active the true measurement covariance is ``r_scale · R_nominal``
    and ``bias_km`` is added to each measurement. The sensor faults of
    issue 15 (item 3) compose with these, all off by default
    (:func:`cwrend_cli.physics.sensors.measurement_noise`); for a step k whose
    measurement carries this window (the window active at t_k):

    * ``dropout_probability`` p_d: no measurement with probability p_d (the
      filter predicts only; 1.0 is a blackout);
    * ``outlier_probability`` p_o, ``outlier_scale`` c: with probability p_o
      the Gaussian part of the noise is multiplied by c (either may be given
      per measurement component, issue 35 item 3: component i is then an
      outlier on its own draw, with probability p_o,i, scaled by c_i) (a contaminated
      Gaussian, Huber 1964, "Robust estimation of a location parameter");
    * ``bias_drift_km_per_sqrt_s`` q: the bias is ``bias_km + d_k`` with
      ``d`` a random walk (Wiener process sampled at the steps,
      Maybeck 1979, *Stochastic Models, Estimation and Control* vol. 1,
      §4.3): d = 0 on the window's first active step, each further active
      step adds an N(0, q² Δt I₃) increment; it does not persist after the
      window.
    """

    start_s: float
    end_s: float
    r_scale: float | tuple[float, ...] = 1.0  # a scalar, or one per measurement component [-]
    bias_km: Vec3 = (0.0, 0.0, 0.0)
    dropout_probability: float = 0.0  # probability of no measurement on a step [-]
    #: probability of an outlier on a step, or one per measurement component [-]
    outlier_probability: float | tuple[float, ...] = 0.0
    #: factor on the Gaussian noise of an outlier, or one per measurement component [-]
    outlier_scale: float | tuple[float, ...] = 1.0
    bias_drift_km_per_sqrt_s: float = 0.0  # random-walk intensity q of the bias [km/√s]
    bias_range_km: float = 0.0  # range_bearing sensor: bias of the range [km]
    bias_angles_deg: tuple[float, float] = (0.0, 0.0)  # nonlinear sensors: (azimuth, elevation)

    @property
    def has_outliers(self) -> bool:
        """True when some component can be an outlier (its probability > 0, its scale ≠ 1)."""
        p, c = self.outlier_probability, self.outlier_scale
        ps = p if isinstance(p, tuple) else (p, p, p)
        cs = c if isinstance(c, tuple) else (c, c, c)
        return any(pi > 0.0 and ci != 1.0 for pi, ci in zip(ps, cs, strict=False))

    @property
    def label(self) -> str:
        """Short description, e.g. ``"R×300 + 17.5 m bias"``."""
        bias_m = 1e3 * math.hypot(*self.bias_km)
        scale = (
            "(" + ", ".join(f"{s:g}" for s in self.r_scale) + ")"
            if isinstance(self.r_scale, tuple)
            else f"{self.r_scale:g}"
        )
        return f"R×{scale}" + (f" + {bias_m:.3g} m bias" if bias_m > 0 else "")


#: The degradation windows of the paper's study (the authors' code; the paper gives no values,
#: docs/method.md): R × 300 on [250, 325], then also a bias.
PAPER_WINDOWS = (
    Window(start_s=250.0, end_s=325.0, r_scale=300.0),
    Window(start_s=325.0, end_s=400.0, r_scale=300.0, bias_km=(0.010, -0.008, 0.012)),
)


@dataclass(frozen=True)
class Degradation:
    """Measurement degradation schedule; later windows win where they overlap."""

    windows: tuple[Window, ...] = PAPER_WINDOWS


#: The sensor models (issue 35; :mod:`cwrend_cli.physics.measurement_models`).
SensorModelName = Literal["position", "range_bearing", "angles"]


@dataclass(frozen=True)
class Sensor:
    """What the chaser measures (issue 35); the paper's relative position by default.

    ``"position"``: the relative position [km] with noise covariance
    ``estimator.r_nominal_km2`` (paper Eq. 13). ``"range_bearing"``: range
    [km], azimuth and elevation of the target seen from the chaser;
    ``"angles"``: azimuth and elevation only. Their noise is diagonal:
    σ_range = ``sigma_range_km`` + ``sigma_range_fraction`` × range,
    σ_angle = ``sigma_angle_deg``
    (:mod:`cwrend_cli.physics.measurement_models`).
    """

    model: SensorModelName = "position"
    sigma_range_km: float = 1e-3  # constant part of the range σ [km]
    sigma_range_fraction: float = 1e-3  # range σ grows by this fraction of the range [-]
    sigma_angle_deg: float = 0.05  # σ of each angle [deg]

    @property
    def dimension(self) -> int:
        """Measurement dimension m (3, or 2 for angles)."""
        return 2 if self.model == "angles" else 3


@dataclass(frozen=True)
class Truth:
    """The dynamics the true relative state obeys (issue 15; :mod:`cwrend_cli.physics.truth`).

    The guidance and the filter use the CW model unless :class:`DesignModel`
    says otherwise (issue 33); ``model`` chooses
    the truth: ``"cw"`` (the same model, stepped exactly), ``"two_body"``
    (exact nonlinear relative motion about a Keplerian chief, in its rotating
    local-vertical frame) or ``"j2"`` (both spacecraft under two-body + J2,
    integrated in an inertial frame). The chief's osculating orbit at t = 0
    has semi-major axis a = (μ/n²)^{1/3} from ``scenario.mean_motion_rad_s``
    (μ of EGM2008, :data:`cwrend_cli.physics.truth.MU_EARTH_KM3_S2`) and the
    elements below; the default is a circular equatorial orbit. Axes: x
    radial, y along-track, z cross-track (along the chief's orbital angular
    momentum).
    """

    model: Literal["cw", "two_body", "j2"] = "cw"
    eccentricity: float = 0.0  # chief eccentricity e, in [0, 1) [-]
    true_anomaly_deg: float = 0.0  # chief true anomaly f at t = 0 [deg]
    inclination_deg: float = 0.0  # chief inclination i, in [0, 180] [deg]
    raan_deg: float = 0.0  # right ascension of the ascending node Ω [deg]
    arg_latitude_deg: float = 0.0  # argument of latitude u = ω + f at t = 0 [deg]


#: The design models a consumer (guidance, filter) can use (issue 33;
#: :mod:`cwrend_cli.physics.design_models`).
DesignModelName = Literal["cw", "ss", "ya"]
#: The filter's models: a design model, or an extended Kalman filter on the truth's
#: nonlinear dynamics (issue 33; :mod:`cwrend_cli.physics.ekf`).
FilterModelName = Literal["cw", "ss", "ya", "ekf_two_body", "ekf_j2"]


@dataclass(frozen=True)
class DesignModel:
    """The linear model each consumer predicts with (issue 33); CW by default.

    ``"cw"``: Clohessy–Wiltshire (paper Eqs. 3–4, the paper's). ``"ss"``:
    Schweighart–Sedwick, J2 with constant coefficients, reference orbit the
    chief's (a from ``scenario.mean_motion_rad_s``, i = ``truth.inclination_deg``).
    ``"ya"``: Yamanaka–Ankersen, the exact transition about the eccentric chief
    of ``[truth]`` (e = ``truth.eccentricity``, f₀ = ``truth.true_anomaly_deg``).
    The filter also takes ``"ekf_two_body"`` or ``"ekf_j2"``: an extended
    Kalman filter on the nonlinear two-body (or two-body + J2) relative
    dynamics about the same chief (:mod:`cwrend_cli.physics.ekf`).
    """

    guidance: DesignModelName = "cw"  # model of the re-solves [-]
    filter: FilterModelName = "cw"  # model of the filter's prediction [-]


@dataclass(frozen=True)
class Actuator:
    """Errors of the thruster between the commanded and the applied control (issue 15, item 2).

    All off by default (an ideal actuator: the applied control is the
    command, bit for bit). The guidance and the filter see only the command;
    the truth receives the applied control :math:`u_a` of step k, built from
    the command :math:`c = u_{k-d}` of ``delay_steps`` = d steps earlier
    (zero for k < d) as (:func:`cwrend_cli.physics.actuator.actuate`)::

        ‖c‖ < min_thrust_km_s2        → u_a = 0           (the thruster does not fire)
        a   = ‖c‖ (1 + magnitude_bias + magnitude_sigma · z_k),  z_k ~ N(0, 1)
        u_a = min(max(a, 0), u_max (1 + magnitude_bias)) · P_k R ĉ

    ``R`` is the fixed misalignment, ``R = R_z(γ) R_y(β) R_x(α)`` with
    ``misalignment_deg = (α, β, γ)``: active right-handed rotations about the
    x (radial), y (along-track) and z (cross-track) axes of the frame the
    control is expressed in, applied in the order x, then y, then z
    (Diebel 2006, "Representing attitude", the 3-2-1 / z-y-x Euler sequence).
    ``P_k`` is the per-step pointing error: a rotation by the vector
    ``ω = σ_p (w − (w·d) d)``, ``w ~ N(0, I₃)``, d = R ĉ, i.e. two independent
    N(0, σ_p²) tilts about axes perpendicular to the thrust, so the angle
    between d and P_k d is ‖ω‖ with ‖ω‖²/σ_p² ~ χ²(2). The magnitude is
    clipped at what the actuator can give, ``u_max (1 + magnitude_bias)``:
    the scale error scales the whole throttle range, the noise never pushes
    the thrust above that ceiling, and never below zero (with no magnitude
    error, a factor of exactly 1, the command passes unchanged: the guidance
    bounds it by u_max). The threshold and the draws of step k apply to the
    delayed command.
    """

    magnitude_bias: float = 0.0  # fixed scale error b of the thrust magnitude, a fraction [-]
    magnitude_sigma: float = 0.0  # per-step magnitude noise σ_m, a fraction of ‖c‖ [-]
    misalignment_deg: Vec3 = (0.0, 0.0, 0.0)  # fixed rotation angles (α, β, γ) about x, y, z [deg]
    pointing_sigma_deg: float = 0.0  # per-step pointing noise σ_p per perpendicular axis [deg]
    min_thrust_km_s2: float = 0.0  # commands with ‖c‖ below this produce nothing [km/s²]
    delay_steps: int = 0  # actuation delay d in whole steps [-]

    @property
    def ideal(self) -> bool:
        """True when every error is off: the applied control is the command."""
        return self == Actuator()

    @property
    def noisy(self) -> bool:
        """True when a per-step random error is on (the run needs actuator draws)."""
        return self.magnitude_sigma > 0.0 or self.pointing_sigma_deg > 0.0


@dataclass(frozen=True)
class KeepOutBody:
    """One more keep-out ellipsoid ``Σ ((r_i − c_i)/a_i)² < 1`` (issue 34), axis-aligned in
    the target's body frame (the relative frame for a fixed target)."""

    centre_km: Vec3  # centre c [km]
    semi_axes_km: Vec3  # semi-axes (a, b, c) [km]


@dataclass(frozen=True)
class KeepOut:
    """A keep-out ellipsoid centred on the target (the relative frame's origin).

    The zone is ``(x/a)² + (y/b)² + (z/c)² < 1`` with ``semi_axes_km = (a, b, c)``
    along x (radial), y (along-track), z (cross-track) [km], united with the
    ellipsoids of ``bodies`` (issue 34). For a tumbling target every axis is a
    body axis.
    """

    semi_axes_km: Vec3  # ellipsoid semi-axes (a, b, c) [km]
    bodies: tuple[KeepOutBody, ...] = ()  # more ellipsoids (issue 34)


@dataclass(frozen=True)
class Corridor:
    """An approach corridor: the cone with apex at the docking port (:mod:`.constraints`).

    Inside the cone ``{r : (r − p)·â ≥ ‖r − p‖ cos θ}`` (p = ``port_km``, â =
    ``axis`` normalised, θ = ``half_angle_deg``) the keep-out zone is waived.
    """

    port_km: Vec3  # docking port p, on or outside the keep-out surface [km]
    axis: Vec3  # outward corridor axis (any length; normalised at use) [-]
    half_angle_deg: float  # cone half-angle θ, in (0, 90) [deg]


@dataclass(frozen=True)
class Constraints:
    """Path constraints of a run (issue 32): a keep-out zone, a corridor, a margin.

    A position is safe when it is outside the keep-out zone or inside the
    corridor. ``sigma_margin`` k tightens every constraint of the constrained
    cone program by k σ along its normal (σ from the filter's position
    covariance) [-].
    """

    keep_out: KeepOut | None = None
    corridor: Corridor | None = None
    sigma_margin: float = 0.0  # covariance margin k, in σ [-]
    #: abort safety (issue 34 item 4, :mod:`.abort_safety`): the free drift from every node
    #: stays outside the keep-out zone for this time [s]; None: off
    abort_safe_s: float | None = None
    #: True: the cone-program guidance plans with them; False: measure only, the guidance
    #: plans as without them and the runs are measured as with them
    enforce: bool = True

    @property
    def active(self) -> bool:
        """True when a keep-out zone or a corridor is configured."""
        return self.keep_out is not None or self.corridor is not None

    @property
    def planned(self) -> bool:
        """True when the cone-program guidance plans with them: a keep-out zone, enforced."""
        return self.enforce and self.keep_out is not None


@dataclass(frozen=True)
class Target:
    """The target's attitude (issue 34; :mod:`.attitude`); ``fixed`` by default.

    ``fixed``: body axes along the relative (Hill) frame at all times, today's
    geometry. ``tumbling``: a torque-free rigid body from the initial attitude
    ``initial_quaternion`` (body→Hill at t = 0, scalar-first, normalised at use),
    the initial ``body_rates_deg_s`` (angular velocity relative to inertial
    space, in body axes) and the principal moments of inertia ``inertia``
    (ratios). The constrained guidance predicts the attitude from the truth's,
    with a knowledge error of σ ``knowledge_sigma_deg`` and
    ``knowledge_sigma_deg_s`` per axis drawn once a run (``knowledge_draw =
    "run"``) or afresh at every re-solve (``"resolve"``)
    (:func:`cwrend_cli.physics.attitude.knowledge_error`).
    """

    attitude: Literal["fixed", "tumbling"] = "fixed"
    initial_quaternion: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)  # [-]
    body_rates_deg_s: Vec3 = (0.0, 0.0, 0.0)  # ω(0), inertial, body axes [deg/s]
    inertia: Vec3 = (1.0, 1.0, 1.0)  # principal moments (I₁, I₂, I₃), ratios [-]
    knowledge_sigma_deg: float = 0.0  # guidance's attitude-knowledge error, σ per axis [deg]
    knowledge_sigma_deg_s: float = 0.0  # its body-rate knowledge error, σ per axis [deg/s]
    knowledge_draw: Literal["run", "resolve"] = "run"  # the error's draw: once, or per re-solve

    @property
    def tumbling(self) -> bool:
        """True for a torque-free tumbling target."""
        return self.attitude == "tumbling"

    @property
    def knowledge_error(self) -> bool:
        """True when the guidance's attitude knowledge has an error (a per-run draw)."""
        return self.tumbling and (
            self.knowledge_sigma_deg > 0.0 or self.knowledge_sigma_deg_s > 0.0
        )


@dataclass(frozen=True)
class Problem:
    """Everything one closed-loop case depends on except the noise realisation."""

    scenario: Scenario = field(default_factory=Scenario)
    estimator: Estimator = field(default_factory=Estimator)
    schedule: Schedule = field(default_factory=Schedule)
    guidance: Guidance = field(default_factory=Guidance)
    solver: Solver = field(default_factory=Solver)
    degradation: Degradation = field(default_factory=Degradation)
    truth: Truth = field(default_factory=Truth)
    actuator: Actuator = field(default_factory=Actuator)
    #: path constraints (issue 32); None: none, every number as without the section
    constraints: Constraints | None = None
    #: design models of the guidance and the filter (issue 33); CW by default
    model: DesignModel = field(default_factory=DesignModel)
    #: the target's attitude (issue 34); fixed in the relative frame by default
    target: Target = field(default_factory=Target)
    #: what the chaser measures (issue 35); the relative position by default
    sensor: Sensor = field(default_factory=Sensor)


@dataclass(frozen=True)
class Architecture:
    """One closed-loop architecture: estimator × schedule × re-solve method.

    ``estimator``: ``"plain"`` (the linear/extended KF), ``"mtf"`` (its
    per-component MTF inflation, paper Eqs. 16–19) or ``"stf"`` (the
    single-factor baseline of issue 35, :func:`cwrend_cli.physics.estimation.
    stf_inflation`). ``method``: the re-solve method (``"shooting"``: the
    costate of the shooting solver; ``"socp"``: the held controls of the
    smoothed minimum-fuel cone program, :mod:`cwrend_cli.physics.guidance.convex`),
    or None for the method of ``guidance.method`` (the paper's four slugs;
    shooting by default).
    """

    slug: str
    estimator: Literal["plain", "mtf", "stf"]
    adaptive: bool
    method: Literal["shooting", "socp"] | None = None

    @property
    def mtf(self) -> bool:
        """True for the MTF filter (paper Eqs. 16–19)."""
        return self.estimator == "mtf"

    @property
    def label(self) -> str:
        """Human-readable name, e.g. ``"MTF KF, adaptive ε"`` (``", SOCP"`` appended for socp)."""
        kf = {"plain": "plain KF", "mtf": "MTF KF", "stf": "STF KF"}[self.estimator]
        tail = ", SOCP" if self.method == "socp" else ""
        return f"{kf}, {'adaptive' if self.adaptive else 'fixed'} ε{tail}"

    def resolved_method(self, guidance: Guidance) -> Literal["shooting", "socp"]:
        """The re-solve method this architecture uses under ``guidance``."""
        return self.method if self.method is not None else guidance.method


#: The ablation of paper Sec. "Numerical Results and Discussion",
#: in the paper's order (``--arch all``).
ARCHITECTURES: Mapping[str, Architecture] = MappingProxyType(
    {
        a.slug: a
        for a in (
            Architecture("plain_fixed", "plain", adaptive=False),
            Architecture("mtf_fixed", "mtf", adaptive=False),
            Architecture("plain_adaptive", "plain", adaptive=True),
            Architecture("mtf_adaptive", "mtf", adaptive=True),
        )
    }
)


def _socp(archs: Mapping[str, Architecture]) -> Mapping[str, Architecture]:
    """The cone-program counterparts of ``archs``, slugs suffixed ``_socp``."""
    return MappingProxyType(
        {
            f"{a.slug}_socp": Architecture(f"{a.slug}_socp", a.estimator, a.adaptive, "socp")
            for a in archs.values()
        }
    )


#: The same four with the cone-program re-solve (issue 16; ``--arch all_socp``).
SOCP_ARCHITECTURES: Mapping[str, Architecture] = _socp(ARCHITECTURES)

#: The single-factor baseline (issue 35), fixed and adaptive ε, shooting then the cone
#: program: in no group of the paper's ablation (``all``, ``all_socp``, ``everything``),
#: only in the ``with_stf`` groups or named (``--arch stf_adaptive,mtf_adaptive``).
_STF_SHOOTING: Mapping[str, Architecture] = MappingProxyType(
    {
        a.slug: a
        for a in (
            Architecture("stf_fixed", "stf", adaptive=False),
            Architecture("stf_adaptive", "stf", adaptive=True),
        )
    }
)
STF_ARCHITECTURES: Mapping[str, Architecture] = MappingProxyType(
    {**_STF_SHOOTING, **_socp(_STF_SHOOTING)}
)

#: Every architecture by slug: what a slug may name (``--arch everything_with_stf``);
#: the single-factor ones last, so that the order of the paper's eight is as before.
ALL_ARCHITECTURES: Mapping[str, Architecture] = MappingProxyType(
    {**ARCHITECTURES, **SOCP_ARCHITECTURES, **STF_ARCHITECTURES}
)


def arch_order(names: Iterable[object]) -> tuple[str, ...]:
    """The distinct architectures of ``names`` in the one display order of every table.

    The order of :data:`ALL_ARCHITECTURES` (the paper's four, their cone-program
    twins, the single-factor baseline), then unknown names sorted: the report,
    ``cwrend table`` and the console tables of ``ablate`` / ``sweep`` list
    architectures in it.
    """
    present = {str(n) for n in names}
    known = [a for a in ALL_ARCHITECTURES if a in present]
    return (*known, *sorted(present - set(known)))
