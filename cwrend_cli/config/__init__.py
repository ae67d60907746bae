"""The cwrend configuration: pydantic models validated once at the boundary, and their I/O.

``schema`` holds the models, ``messages`` the error texts, ``overrides`` every
dotted-key operation, ``io`` files (TOML, noise) and ``adapt`` the conversion
into the physics core's typed parameters. The names below are the public API;
:class:`Architecture` and :data:`ARCHITECTURES` are the physics core's
(:mod:`cwrend_cli.physics.params`), re-exported here for the user-facing code.
"""

from cwrend_cli.config.io import (
    config_from_dict,
    config_hash,
    load_config,
    resolved_dict,
    shown_dict,
    to_json,
    to_toml,
)
from cwrend_cli.config.messages import format_validation_error
from cwrend_cli.config.overrides import (
    apply,
    expand_grid,
    get_dotted,
    parse_arch,
    parse_archs,
    parse_override,
    parse_param,
    replaced_sweep_keys,
    set_dotted,
)
from cwrend_cli.config.schema import (
    ActuatorConfig,
    CwrendConfig,
    DegradationConfig,
    DegradationWindow,
    Dispersion,
    EstimatorConfig,
    GuidanceConfig,
    NoiseConfig,
    OutputConfig,
    ScenarioConfig,
    ScheduleConfig,
    SolverConfig,
    TruthConfig,
)
from cwrend_cli.physics.params import (
    ALL_ARCHITECTURES,
    ARCHITECTURES,
    SOCP_ARCHITECTURES,
    STF_ARCHITECTURES,
    Architecture,
)

__all__ = [
    "ALL_ARCHITECTURES",
    "ARCHITECTURES",
    "SOCP_ARCHITECTURES",
    "STF_ARCHITECTURES",
    "ActuatorConfig",
    "Architecture",
    "CwrendConfig",
    "DegradationConfig",
    "DegradationWindow",
    "Dispersion",
    "EstimatorConfig",
    "GuidanceConfig",
    "NoiseConfig",
    "OutputConfig",
    "ScenarioConfig",
    "ScheduleConfig",
    "SolverConfig",
    "TruthConfig",
    "apply",
    "config_from_dict",
    "config_hash",
    "expand_grid",
    "format_validation_error",
    "get_dotted",
    "load_config",
    "parse_arch",
    "parse_archs",
    "parse_override",
    "parse_param",
    "replaced_sweep_keys",
    "resolved_dict",
    "set_dotted",
    "shown_dict",
    "to_json",
    "to_toml",
]
