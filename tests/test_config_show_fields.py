"""``cwrend config show`` lists every field of the schema, defaults included.

The resolved tree the hashes are computed from leaves default-valued fields out
(the schema's ``model_serializer``s, so that hashes stay as they were); ``config
show`` must not: its help and docs/guide/config.md promise every field.
"""

from __future__ import annotations

import json
import tomllib
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from pydantic import BaseModel
from typer.testing import CliRunner

from cwrend_cli.cli import app
from cwrend_cli.config import (
    CwrendConfig,
    config_from_dict,
    config_hash,
    load_config,
    resolved_dict,
)
from cwrend_cli.config.io import to_toml

CAMPAIGNS = Path(__file__).resolve().parents[1] / "campaigns"
CONFIGS = ("paper.toml", "safe_approach.toml", "tumbling_target.toml")
runner = CliRunner()

KeyPath = tuple[str | int, ...]


def _schema_fields(model: BaseModel, path: KeyPath = ()) -> Iterator[tuple[KeyPath, Any]]:
    """Every field of ``model`` by ``model_fields``, recursively: (dotted path, value).

    Sub-models are walked too, also inside lists (``degradation.windows``) and
    tables (``dispersions``).
    """
    for name in type(model).model_fields:
        value = getattr(model, name)
        here = (*path, name)
        yield here, value
        if isinstance(value, BaseModel):
            yield from _schema_fields(value, here)
        elif isinstance(value, (tuple, list)):
            for i, item in enumerate(value):
                if isinstance(item, BaseModel):
                    yield from _schema_fields(item, (*here, i))
        elif isinstance(value, dict):
            for key, item in value.items():
                if isinstance(item, BaseModel):
                    yield from _schema_fields(item, (*here, key))


def _lookup(tree: Any, path: KeyPath) -> tuple[bool, Any]:
    """(found, value) of ``path`` in a parsed TOML/JSON tree."""
    for key in path:
        if isinstance(key, int):
            if not isinstance(tree, list) or key >= len(tree):
                return False, None
        elif not isinstance(tree, dict) or key not in tree:
            return False, None
        tree = tree[key]
    return True, tree


def _unset_comments(text: str) -> set[KeyPath]:
    """Dotted paths of the ``# key = (unset)`` lines of ``config show``, by their table."""
    table: KeyPath = ()
    found: set[KeyPath] = set()
    for line in text.splitlines():
        if line.startswith("[") and not line.startswith("[["):
            node: Any = tomllib.loads(line)  # the header's keys, quoted ones too
            keys: list[str] = []
            while isinstance(node, dict) and node:
                (key,) = node
                keys.append(key)
                node = node[key]
            table = tuple(keys)
        elif line.startswith("[["):
            table = ("<array of tables>",)
        elif line.startswith("# ") and line.endswith(" = (unset)"):
            found.add((*table, line[2 : -len(" = (unset)")]))
    return found


def _show(config: str, *extra: str) -> str:
    result = runner.invoke(app, ["config", "show", str(CAMPAIGNS / config), *extra])
    assert result.exit_code == 0, result.output
    return result.stdout


@pytest.mark.parametrize("config", CONFIGS)
def test_config_show_toml_lists_every_schema_field(config: str) -> None:
    cfg = load_config(CAMPAIGNS / config)
    text = _show(config)
    shown = tomllib.loads(text)
    unset = _unset_comments(text)
    missing = []
    for path, value in _schema_fields(cfg):
        ok = path in unset if value is None else _lookup(shown, path)[0]
        if not ok:
            missing.append(".".join(map(str, path)))
    assert not missing, f"config show {config} leaves out: {', '.join(missing)}"
    # and it still reads back as the same config, with the same hash printed
    assert config_from_dict(shown, base_dir=CAMPAIGNS) == cfg
    assert f"# config_hash = {config_hash(cfg)}" in text


@pytest.mark.parametrize("config", CONFIGS)
def test_config_show_json_lists_every_schema_field(config: str) -> None:
    cfg = load_config(CAMPAIGNS / config)
    shown = json.loads(_show(config, "--format", "json"))
    missing = []
    for path, value in _schema_fields(cfg):
        found, got = _lookup(shown, path)
        if not found or (got is None) != (value is None):  # unset: null
            missing.append(".".join(map(str, path)))
    assert not missing, f"config show --format json {config} leaves out: {', '.join(missing)}"


def _superset(full: Any, reduced: Any, path: str = "") -> None:
    """Every value of ``reduced`` is in ``full``, equal; ``full`` may hold more keys."""
    if isinstance(reduced, dict):
        assert isinstance(full, dict), path
        for key, value in reduced.items():
            assert key in full, f"{path}.{key}"
            _superset(full[key], value, f"{path}.{key}")
    elif isinstance(reduced, list):
        assert isinstance(full, list) and len(full) == len(reduced), path
        for i, (a, b) in enumerate(zip(full, reduced, strict=True)):
            _superset(a, b, f"{path}.{i}")
    else:
        assert full == reduced, path


@pytest.mark.parametrize("config", CONFIGS)
def test_config_show_values_are_those_of_the_hashed_tree(config: str) -> None:
    cfg = load_config(CAMPAIGNS / config)
    shown = json.loads(_show(config, "--format", "json"))
    _superset(shown, resolved_dict(cfg))
    assert config_hash(config_from_dict(shown, base_dir=CAMPAIGNS)) == config_hash(cfg)


def test_the_hashed_tree_still_leaves_the_defaults_out() -> None:
    # config show lists them; the tree the hashes are computed from does not (hashes pinned)
    tree = resolved_dict(CwrendConfig())
    for section in ("constraints", "model", "sensor", "target"):
        assert section not in tree
    assert "process_noise" not in tree["estimator"]


@pytest.mark.parametrize("config", sorted(p.name for p in CAMPAIGNS.glob("*.toml")))
def test_config_show_of_every_campaign_reads_back_as_the_same_config(config: str) -> None:
    """Every shipped campaign, dispersions included: the unset comments of a dispersion's
    table go under its quoted header (``[dispersions."scenario.x0.2"]``), not under an
    unquoted one that TOML reads as nested tables (which did not read back)."""
    cfg = load_config(CAMPAIGNS / config)
    back = config_from_dict(tomllib.loads(to_toml(cfg, show_unset=True)))
    assert config_hash(back) == config_hash(cfg)
