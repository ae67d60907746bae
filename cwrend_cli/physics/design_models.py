"""Design models beyond Clohessy–Wiltshire: eccentric chief (``ya``) and J2 (``ss``).

The guidance and the filter of the paper use the CW model (paper Eqs. 3–4,
11; :mod:`cwrend_cli.physics.dynamics`). This module gives two linear models
that describe the orbit better, each as its exact zero-order-hold
discretisation over one step, ``x_{k+1} = Φ_k x_k + Γ_k u_k``:

* ``"ss"`` — Schweighart & Sedwick, "High-Fidelity Linearized J2 Model for
  Satellite Formation Flight", J. Guid. Control Dyn. 25(6), 1073–1080, 2002. The
  gradient of the J2 acceleration averaged over one orbit of a circular
  reference orbit of radius r_ref and inclination i gives linear equations
  with constant coefficients (the paper's linearised equations of motion and
  its constants s and c, cited here by formula: their equation numbers were
  not checked against a copy of the paper)::

      s  = (3 J2 R_E² / (8 r_ref²)) (1 + 3 cos 2i)          [-]
      c  = √(1 + s)                                         [-]
      ẍ − 2(nc) ẏ − (5c² − 2) n² x = u_x
      ÿ + 2(nc) ẋ                 = u_y
      z̈ + (3c² − 2) n² z          = u_z

  n = √(μ/r_ref³); nc is the rate of the reference frame. Included: the
  in-plane equations with their constant J2 coefficients and the linear
  cross-track equation of the averaged gradient. Left out: the forcing
  terms of the x and y equations (the J2 acceleration of the reference
  orbit itself: the same for chief and deputy to first order, so they cancel
  in the relative motion between two spacecraft) and the paper's refined
  cross-track solution with its amplitude l and phase φ (the differential
  nodal drift, which depends on the deputy's inclination and node, not
  linearly on the relative state). (The coefficients are written from the
  paper's model and checked here against a direct derivation: the
  orbit-averaged J2 radial acceleration at r_ref is s n² r_ref, its
  radial gradient 4 s n², its cross-track gradient 3 s n², so the frame rate
  is n√(1 + s) and the stiffnesses are n²(1 + s) + 2n² + 4sn² = (5c² − 2) n²
  and n² + 3sn² = (3c² − 2) n².) At J2 = 0, c = 1 and the model is CW.
  The reference orbit here is the chief's: r_ref = a = (μ/n²)^{1/3} from
  ``scenario.mean_motion_rad_s`` and i from ``truth.inclination_deg``.

* ``"ya"`` — Yamanaka & Ankersen, "New State Transition Matrix for Relative
  Motion on an Arbitrary Elliptical Orbit", J. Guid. Control Dyn. 25(1),
  2002: the exact solution of the Tschauner–Hempel equations (the linearised
  relative motion about a Keplerian chief of any eccentricity e < 1). With
  the true anomaly f as the independent variable, ρ = 1 + e cos f,
  k² = √(μ/p³) (so that ḟ = k² ρ²) and the scaled coordinates
  x̃ = ρ x (same for y, z; ′ = d/df), the equations are (cwrend's axes:
  x radial outward, y along-track, z cross-track; YA write theirs with
  x along-track and z radially inward, the same solution in other axes)::

      x̃″ = 3 x̃/ρ + 2 ỹ′,   ỹ″ = −2 x̃′,   z̃″ = −z̃

  and the physical state maps to the scaled one by
  x̃′ = ẋ/(k²ρ) − e sin f · x (inverse ẋ = k² (ρ x̃′ + e sin f · x̃)).
  A fundamental set of solutions (YA's, with s = ρ sin f, c = ρ cos f and
  their integral J = k²(t − t_ref) = ∫ df/ρ²)::

      (x̃, ỹ) = (s, c (1 + 1/ρ))
               (c, −s (1 + 1/ρ))
               (2 − 3 e s J, −3 ρ² J)
               (0, 1)
      z̃      = cos f, sin f

  (ỹ′ + 2x̃ is constant along each: 0, e, 1 and 0). The transition from t to τ is
  Φ(τ, t) = T(τ) Ψ(τ) Ψ(t)⁻¹ T(t)⁻¹ with Ψ this 6×6 fundamental matrix and
  T the map from scaled to physical state, J and f measured from t (so
  Ψ(t) is well conditioned and the step loses no digits). f(t) comes from
  Kepler's equation M = E − e sin E (Newton's method to machine precision),
  M = M₀ + n t. At e = 0 the solution is CW: ρ = 1, k² = n, f = f₀ + nt.

  The chief is the truth's: a = (μ/n²)^{1/3}, e = ``truth.eccentricity``,
  f₀ = ``truth.true_anomaly_deg`` at t = 0 (:func:`ya_chief`).

Input matrices. The ``ss`` model is time-invariant and its Γ = ∫₀^Δt e^{Aτ}B dτ
is written in closed form (:func:`lti_input_matrix`), as CW's. The ``ya``
transition has no closed-form zero-order-hold integral; Γ_k =
∫_{t_k}^{t_{k+1}} Φ(t_{k+1}, τ) B dτ is computed by Gauss–Legendre quadrature
with :data:`GAUSS_NODES` nodes on panels short enough that the chief's
largest rate ḟ_max = k²(1 + e)² times the panel length is at most
:data:`PANEL_PHASE`: the m-point rule's error on a panel of length h is
h^{2m+1} (m!)⁴ / ((2m + 1) ((2m)!)³) · max |g^{(2m)}|, and the integrand's
derivatives grow like ḟ_max^{2m} (times the rational factors of ρ, at most
((1 + e)/(1 − e))^{2m}), so the relative error is below
0.25^{16} · 1.9e-23 ≈ 4.5e-33 for e ≤ 0.5 and h ḟ_max ≤ 0.25 — far below
double-precision rounding (2.2e-16), which is what the quadrature returns.

Units: km, s, km/s, km/s², rad/s. State ``[x, y, z, ẋ, ẏ, ż]``. Pure
functions on plain floats and arrays.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from cwrend_cli.physics.dynamics import discretize, one_minus_cos, x_minus_sin
from cwrend_cli.physics.lti_kernels import LtiKernel, transition
from cwrend_cli.physics.params import (
    Architecture,
    DesignModel,
    DesignModelName,
    FloatArray,
    Guidance,
    Scenario,
    Truth,
)
from cwrend_cli.physics.truth import (
    J2_EARTH,
    MU_EARTH_KM3_S2,
    R_EARTH_KM,
    semi_major_axis_km,
)

#: Gauss–Legendre nodes per panel of the ``ya`` input matrix (module docstring).
GAUSS_NODES = 8
#: Largest ḟ_max · h of one quadrature panel [rad] (module docstring).
PANEL_PHASE = 0.25

_GL_X, _GL_W = np.polynomial.legendre.leggauss(GAUSS_NODES)


# ---------------------------------------------------------------------------
# Time-invariant models: CW and Schweighart–Sedwick, one closed form
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class LinearTimeInvariant:
    """``ẍ = α x + β ẏ + u_x``, ``ÿ = −β ẋ + u_y``, ``z̈ = −q² z + u_z``.

    CW: α = 3n², β = 2n, q = n. Schweighart–Sedwick: α = (5c² − 2) n²,
    β = 2nc, q² = (3c² − 2) n². The in-plane frequency is ω = √(β² − α)
    (n for CW, n√(2 − c²) for SS).
    """

    alpha: float  # radial stiffness α [1/s²]
    beta: float  # Coriolis coefficient β [rad/s]
    q: float  # cross-track frequency q [rad/s]

    @property
    def omega(self) -> float:
        """In-plane frequency ω = √(β² − α) [rad/s]."""
        return math.sqrt(self.beta * self.beta - self.alpha)

    def system(self) -> tuple[FloatArray, FloatArray]:
        """State and input matrices ``A`` (6×6) and ``B`` (6×3)."""
        a = np.zeros((6, 6))
        a[0:3, 3:6] = np.eye(3)
        a[3, 0] = self.alpha
        a[3, 4] = self.beta
        a[4, 3] = -self.beta
        a[5, 2] = -self.q * self.q
        b = np.zeros((6, 3))
        b[3:6, :] = np.eye(3)
        return a, b

    def kernel(self) -> LtiKernel:
        """The coefficients as the compiled kernels take them (:mod:`.lti_kernels`)."""
        return LtiKernel(alpha=self.alpha, beta=self.beta, q=self.q, omega=self.omega)


@dataclass(frozen=True)
class SchweighartSedwick:
    """The constants of the Schweighart–Sedwick model (module docstring)."""

    n: float  # mean motion of the reference orbit n = √(μ/r_ref³) [rad/s]
    s: float  # s = (3 J2 R_E²/(8 r_ref²)) (1 + 3 cos 2i) [-]
    c: float  # c = √(1 + s) [-]

    def lti(self) -> LinearTimeInvariant:
        """α = (5c² − 2) n², β = 2nc, q = n √(3c² − 2)."""
        n, c2 = self.n, self.c * self.c
        return LinearTimeInvariant(
            alpha=(5.0 * c2 - 2.0) * n * n, beta=2.0 * n * self.c, q=n * math.sqrt(3.0 * c2 - 2.0)
        )


def schweighart_sedwick(
    n: float, r_ref_km: float, inclination_deg: float, j2: float, r_e_km: float
) -> SchweighartSedwick:
    """s and c of a reference orbit of radius ``r_ref_km``, inclination ``inclination_deg``.

    ``n`` [rad/s] is its mean motion, ``j2`` [-] and ``r_e_km`` [km] Earth's J2
    and reference radius.
    """
    i = math.radians(inclination_deg)
    s = 3.0 * j2 * r_e_km * r_e_km / (8.0 * r_ref_km * r_ref_km) * (1.0 + 3.0 * math.cos(2.0 * i))
    return SchweighartSedwick(n=n, s=s, c=math.sqrt(1.0 + s))


def lti_stm(m: LinearTimeInvariant, t: float) -> FloatArray:
    """``Φ(t) = e^{At}`` of :class:`LinearTimeInvariant` in closed form (6×6); valid for t < 0.

    :func:`cwrend_cli.physics.lti_kernels.transition` (its docstring has the
    formulas; 1 − cos θ and θ − sin θ without cancellation, as CW's Eq. 11 in
    :func:`cwrend_cli.physics.dynamics.stm`), the one the compiled shooting
    kernels use.
    """
    return np.asarray(transition(m.kernel(), t))


def lti_input_matrix(m: LinearTimeInvariant, t: float) -> FloatArray:
    """Zero-order-hold ``Γ(t) = ∫₀ᵗ e^{Aτ} B dτ`` (6×3) in closed form.

    The integrals of the velocity columns of :func:`lti_stm`; the y entry of
    the along-track column is −α t²/(2ω²) + β² (1 − cos θ)/ω⁴.
    """
    w, al, be = m.omega, m.alpha, m.beta
    th = w * t
    s = math.sin(th)
    omc, xms = one_minus_cos(th), x_minus_sin(th)
    w2, w3 = w * w, w * w * w
    g = np.zeros((6, 3))
    g[0, 0] = omc / w2
    g[1, 0] = -be * xms / w3
    g[3, 0] = s / w
    g[4, 0] = -be * omc / w2
    g[0, 1] = be * xms / w3
    g[1, 1] = -al * t * t / (2.0 * w2) + be * be * omc / (w2 * w2)
    g[3, 1] = be * omc / w2
    g[4, 1] = t - be * be * xms / w3
    qt = m.q * t
    g[2, 2] = one_minus_cos(qt) / (m.q * m.q)
    g[5, 2] = math.sin(qt) / m.q
    return g


# ---------------------------------------------------------------------------
# Yamanaka–Ankersen: eccentric chief
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class EccentricChief:
    """A Keplerian chief orbit: mean motion, eccentricity and true anomaly at t = 0."""

    n: float  # mean motion n = √(μ/a³) [rad/s]
    e: float  # eccentricity, in [0, 1) [-]
    f0: float  # true anomaly at t = 0 [rad]
    mu: float  # gravitational parameter μ [km³/s²]

    @property
    def k2(self) -> float:
        """k² = √(μ/p³), so that ḟ = k² ρ² [rad/s]."""
        a = (self.mu / (self.n * self.n)) ** (1.0 / 3.0)
        p = a * (1.0 - self.e * self.e)
        return math.sqrt(self.mu / (p * p * p))

    def true_anomaly(self, t: float) -> float:
        """True anomaly f(t) [rad], continuous in t (not wrapped), f(0) = f0.

        Kepler's equation M = E − e sin E solved by Newton's method from
        M = M(f0) + n t; f = E + 2 atan(β sin E/(1 − β cos E)),
        β = e/(1 + √(1 − e²)), which is continuous in E.
        """
        e = self.e
        if e == 0.0:
            return self.f0 + self.n * t
        beta = e / (1.0 + math.sqrt(1.0 - e * e))
        e0 = self.f0 - 2.0 * math.atan2(beta * math.sin(self.f0), 1.0 + beta * math.cos(self.f0))
        m = e0 - e * math.sin(e0) + self.n * t
        big_e = m + e * math.sin(m)
        for _ in range(50):
            step = (big_e - e * math.sin(big_e) - m) / (1.0 - e * math.cos(big_e))
            big_e -= step
            if abs(step) <= 1e-15 * max(1.0, abs(big_e)):
                break
        return big_e + 2.0 * math.atan2(beta * math.sin(big_e), 1.0 - beta * math.cos(big_e))


def _ya_fundamental(e: float, f: float, j: float) -> FloatArray:
    """Fundamental matrix Ψ (6×6) of the scaled Tschauner–Hempel equations at f.

    Rows x̃, ỹ, z̃, x̃′, ỹ′, z̃′; ``j`` = J = k²(t − t_ref) [-].
    """
    sf, cf = math.sin(f), math.cos(f)
    rho = 1.0 + e * cf
    s, c = rho * sf, rho * cf
    ds = cf + e * math.cos(2.0 * f)  # s′
    dc = -(sf + e * math.sin(2.0 * f))  # c′
    psi = np.zeros((6, 6))
    # column 1: x̃ = s, ỹ = c (1 + 1/ρ)
    psi[0, 0] = s
    psi[1, 0] = c * (1.0 + 1.0 / rho)
    psi[3, 0] = ds
    psi[4, 0] = -2.0 * s
    # column 2: x̃ = c, ỹ = −s (1 + 1/ρ) (here ỹ′ + 2x̃ = e)
    psi[0, 1] = c
    psi[1, 1] = -s * (1.0 + 1.0 / rho)
    psi[3, 1] = dc
    psi[4, 1] = e - 2.0 * c
    # column 3: x̃ = 2 − 3 e s J, ỹ = −3 ρ² J
    psi[0, 2] = 2.0 - 3.0 * e * s * j
    psi[1, 2] = -3.0 * rho * rho * j
    psi[3, 2] = -3.0 * e * (ds * j + s / (rho * rho))
    psi[4, 2] = -3.0 + 6.0 * e * s * j
    # column 4: ỹ = 1
    psi[1, 3] = 1.0
    # cross-track: z̃ = cos f, sin f
    psi[2, 4] = cf
    psi[5, 4] = -sf
    psi[2, 5] = sf
    psi[5, 5] = cf
    return psi


def _per_axis(position: float, coupling: float, velocity: float) -> FloatArray:
    """6×6 [[position·I, 0], [coupling·I, velocity·I]]: the same 2×2 map on each axis."""
    t = np.zeros((6, 6))
    for i in range(3):
        t[i, i] = position
        t[3 + i, i] = coupling
        t[3 + i, 3 + i] = velocity
    return t


def _to_physical(e: float, k2: float, f: float) -> FloatArray:
    """T(f) (6×6): scaled state [x̃, x̃′] → physical [x, ẋ] per axis (module docstring)."""
    rho = 1.0 + e * math.cos(f)
    return _per_axis(1.0 / rho, k2 * (e * math.sin(f)), k2 * rho)


def _to_scaled(e: float, k2: float, f: float) -> FloatArray:
    """T(f)⁻¹ (6×6): physical [x, ẋ] → scaled [x̃, x̃′] = [ρx, ẋ/(k²ρ) − e sin f · x]."""
    rho = 1.0 + e * math.cos(f)
    return _per_axis(rho, -(e * math.sin(f)), 1.0 / (k2 * rho))


def ya_stm(chief: EccentricChief, t0: float, t1: float) -> FloatArray:
    """Yamanaka–Ankersen transition Φ(t1, t0) (6×6) of the physical relative state.

    Exact solution of the Tschauner–Hempel equations (module docstring);
    ``t0``, ``t1`` [s] from the chief's epoch (where f = f0). Valid for t1 < t0.
    """
    f0 = chief.true_anomaly(t0)
    f1 = chief.true_anomaly(t1)
    return _ya_stm_f(chief, f0, f1, t1 - t0)


def _ya_stm_f(chief: EccentricChief, f0: float, f1: float, dt: float) -> FloatArray:
    e, k2 = chief.e, chief.k2
    psi0 = _ya_fundamental(e, f0, 0.0)
    psi1 = _ya_fundamental(e, f1, k2 * dt)
    # Φ = T(f1) Ψ(f1) Ψ(f0)⁻¹ T(f0)⁻¹
    inner = np.linalg.solve(psi0.T, psi1.T).T  # Ψ(f1) Ψ(f0)⁻¹
    return np.asarray(_to_physical(e, k2, f1) @ inner @ _to_scaled(e, k2, f0))


def ya_input_matrix(chief: EccentricChief, t0: float, t1: float) -> FloatArray:
    """Zero-order-hold Γ = ∫_{t0}^{t1} Φ(t1, τ) B dτ (6×3) by Gauss–Legendre quadrature.

    :data:`GAUSS_NODES` nodes per panel, panels with ḟ_max h ≤ :data:`PANEL_PHASE`
    (accuracy: module docstring). B = [0; I₃].
    """
    e = chief.e
    f_dot_max = chief.k2 * (1.0 + e) * (1.0 + e)
    length = t1 - t0
    panels = max(1, math.ceil(abs(length) * f_dot_max / PANEL_PHASE))
    h = length / panels
    f1 = chief.true_anomaly(t1)
    g = np.zeros((6, 3))
    for p in range(panels):
        a = t0 + p * h
        for x, w in zip(_GL_X, _GL_W, strict=True):
            tau = a + 0.5 * h * (1.0 + float(x))
            phi = _ya_stm_f(chief, chief.true_anomaly(tau), f1, t1 - tau)
            g += (0.5 * h * float(w)) * phi[:, 3:6]
    return g


# ---------------------------------------------------------------------------
# Per-step tables of a scenario (what the guidance and the filter consume)
# ---------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class StepTables:
    """Φ_k = Φ(t_{k+1}, t_k) and Γ_k of every step k = 0 … N−1 of a scenario (read-only)."""

    phi: FloatArray  # (N, 6, 6)
    gam: FloatArray  # (N, 6, 3) [s, s²]
    time_invariant: bool  # every step's Φ_k, Γ_k is the same


def ya_chief(truth: Truth, scenario: Scenario) -> EccentricChief:
    """The Keplerian chief of ``[truth]``: n of the scenario, e, f0 (the ``ya`` model's)."""
    return EccentricChief(
        n=scenario.mean_motion_rad_s,
        e=truth.eccentricity,
        f0=math.radians(truth.true_anomaly_deg),
        mu=MU_EARTH_KM3_S2,
    )


def ss_model(truth: Truth, scenario: Scenario) -> LinearTimeInvariant:
    """The ``ss`` model of the chief: r_ref = a = (μ/n²)^{1/3}, i of ``[truth]``, EGM2008's J2."""
    n = scenario.mean_motion_rad_s
    ss = schweighart_sedwick(n, semi_major_axis_km(n), truth.inclination_deg, J2_EARTH, R_EARTH_KM)
    return ss.lti()


@functools.lru_cache(maxsize=16)
def step_tables(name: DesignModelName, scenario: Scenario, truth: Truth) -> StepTables:
    """The tables of design model ``name`` on the grid t_k = k Δt of ``scenario``.

    ``"cw"``: Eq. 11 (:func:`cwrend_cli.physics.dynamics.discretize`); ``"ss"``:
    :func:`lti_stm`, :func:`lti_input_matrix`; ``"ya"``: :func:`ya_stm`,
    :func:`ya_input_matrix` step by step (time-varying). Cached per scenario
    and truth (both frozen): a campaign's runs share one table.
    """
    steps, dt = scenario.n_steps, scenario.dt_s
    if name == "ya":
        chief = ya_chief(truth, scenario)
        phi = np.empty((steps, 6, 6))
        gam = np.empty((steps, 6, 3))
        for k in range(steps):
            phi[k] = ya_stm(chief, k * dt, (k + 1) * dt)
            gam[k] = ya_input_matrix(chief, k * dt, (k + 1) * dt)
    else:
        if name == "ss":
            lti = ss_model(truth, scenario)
            one_phi, one_gam = lti_stm(lti, dt), lti_input_matrix(lti, dt)
        else:
            one_phi, one_gam = discretize(scenario.mean_motion_rad_s, dt)
        phi = np.repeat(one_phi[None], steps, axis=0)
        gam = np.repeat(one_gam[None], steps, axis=0)
    phi.flags.writeable = False
    gam.flags.writeable = False
    return StepTables(phi=phi, gam=gam, time_invariant=name != "ya")


def unsupported(
    model: DesignModel, arch: Architecture, guidance: Guidance, constrained: bool = False
) -> str | None:
    """Why ``arch`` cannot fly ``model`` yet (a sentence naming the field), or None.

    The cone-program re-solve (``socp``) takes any model (it needs Φ_k, Γ_k
    only) when unconstrained; the constrained cone program
    (:mod:`cwrend_cli.physics.guidance.constrained`, with ``[constraints]``) plans
    with CW (Eq. 11) so far. The shooting re-solve's compiled kernels take CW and
    the time-invariant ``ss`` (:mod:`cwrend_cli.physics.lti_kernels`), not the
    time-varying ``ya``: they evaluate the primer vector Bᵀ Φ(T, t)ᵀ ν and its
    time derivatives in closed form at any time of the horizon (quadrature nodes,
    switching-time roots), and YA's Φ(T, t) needs Kepler's equation and a 6×6
    solve at each of those times; a table on the 1 s grid would not do.
    """
    if model.guidance == "cw":
        return None
    method = arch.resolved_method(guidance)
    if method == "shooting" and model.guidance == "ya":
        return (
            f"model.guidance = 'ya' with architecture {arch.slug}: its shooting re-solve "
            "takes 'cw' and 'ss' only (the compiled kernels need the transition in closed "
            "form at any time; Yamanaka–Ankersen's is time-varying); use the cone-program "
            "architectures (--arch all_socp, or guidance.method = 'socp')"
        )
    if constrained and method != "shooting":
        return (
            f"model.guidance = '{model.guidance}' with [constraints] and architecture "
            f"{arch.slug}: the constrained cone program plans with 'cw' only so far; set "
            "model.guidance = 'cw' or drop [constraints]"
        )
    return None
