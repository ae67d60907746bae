"""The ``[model]`` section (issue 33 item 1): design models of the guidance and the filter.

Default CW everywhere: without the section (or with it at its defaults) the resolved
tree, the config hash and the typed problem are those of today's configs, so every
campaign hash and number is unchanged. ``"ss"`` and ``"ya"`` read the chief's orbit
from ``[truth]``; a truth that flies no chief (``"cw"``) is refused naming the field,
exit 2.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from cwrend_cli.cli import app
from cwrend_cli.config.adapt import problem_of
from cwrend_cli.config.io import config_from_dict, config_hash, resolved_dict
from cwrend_cli.config.schema import CwrendConfig, ModelConfig
from cwrend_cli.physics import params

runner = CliRunner()
REPO = Path(__file__).resolve().parents[1]
J2_TRUTH = {"model": "j2", "inclination_deg": 51.6}


@pytest.mark.parametrize("table", [{}, {"guidance": "cw"}, {"guidance": "cw", "filter": "cw"}])
def test_a_config_without_a_design_model_keeps_its_hash_and_tree(table: dict[str, str]) -> None:
    written = config_from_dict({"model": table})
    default = CwrendConfig()
    assert "model" not in resolved_dict(written)
    assert config_hash(written) == config_hash(default)
    assert config_hash(CwrendConfig(model=ModelConfig())) == config_hash(default)
    assert problem_of(written) == params.Problem()


def test_the_typed_problem_carries_the_design_models() -> None:
    cfg = config_from_dict({"truth": J2_TRUTH, "model": {"guidance": "ss", "filter": "ss"}})
    assert problem_of(cfg).model == params.DesignModel(guidance="ss", filter="ss")
    tree = resolved_dict(cfg)
    assert tree["model"] == {"guidance": "ss", "filter": "ss"}
    assert config_from_dict(tree) == cfg
    assert config_hash(cfg) != config_hash(config_from_dict({"truth": J2_TRUTH}))


def _validate(*sets: str, file: str = "campaigns/paper.toml") -> tuple[int, str]:
    args = ["config", "validate", str(REPO / file)]
    for s in sets:
        args += ["--set", s]
    result = runner.invoke(app, args)
    return result.exit_code, result.output


@pytest.mark.parametrize(
    ("sets", "field", "words"),
    [
        (("model.guidance='ss'",), "model.guidance", "truth.model = 'two_body' or 'j2'"),
        (("model.filter='ya'",), "model.filter", "truth.model = 'two_body' or 'j2'"),
        (("model.guidance='gim'",), "model.guidance", "one of 'cw', 'ss' or 'ya'"),
    ],
)
def test_a_bad_design_model_exits_2_naming_the_field(
    sets: tuple[str, ...], field: str, words: str
) -> None:
    code, out = _validate(*sets)
    assert code == 2, out
    assert field in out and words in out, out
    assert "Traceback" not in out


def test_ss_and_ya_guidance_validate_with_a_chief() -> None:
    code, out = _validate(
        "model.guidance='ss'", "model.filter='ss'", file="campaigns/paper_j2.toml"
    )
    assert code == 0 and out.startswith("OK "), out
    code, out = _validate(
        "truth.model='two_body'",
        "truth.eccentricity=0.05",
        "model.guidance='ya'",
        "model.filter='ya'",
    )
    assert code == 0 and out.startswith("OK "), out
