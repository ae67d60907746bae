"""The cwrend configuration: pydantic models validated once at the boundary, and their I/O.

``schema`` holds the models, ``messages`` the error texts, ``overrides`` every
dotted-key operation, ``io`` files (TOML, noise) and ``adapt`` the conversion
into the physics core's typed parameters.
"""

from cwrend_cli.config.schema import (
    ARCHITECTURES,
    Architecture,
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
    config_from_dict,
    config_hash,
    format_validation_error,
    load_config,
    parse_arch,
    parse_override,
    resolved_dict,
    set_dotted,
    to_json,
    to_toml,
)

__all__ = [
    "ARCHITECTURES",
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
    "config_from_dict",
    "config_hash",
    "format_validation_error",
    "load_config",
    "parse_arch",
    "parse_override",
    "resolved_dict",
    "set_dotted",
    "to_json",
    "to_toml",
]
