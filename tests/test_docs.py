"""The manual: the configuration reference is the schema's, every value has a meaning and a unit.

The reference page (``docs/reference/config.md``) is generated at build time by the MkDocs
hook ``docs/hooks/config_reference.py`` from :class:`cwrend_cli.config.schema.CwrendConfig`;
these tests read the same walk of the schema the hook renders.
"""

from __future__ import annotations

import importlib.util
import re
import sys
from pathlib import Path
from types import ModuleType

import pytest

REPO = Path(__file__).resolve().parents[1]


def _hook() -> ModuleType:
    name = "cwrend_docs_config_reference"
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, REPO / "docs/hooks/config_reference.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


LEAVES = _hook().leaf_fields()


def test_the_schema_has_the_paper_scenario_values() -> None:
    keys = {leaf.key for leaf in LEAVES}
    assert {"scenario.horizon_s", "schedule.beta", "degradation.windows.<i>.bias_km"} <= keys
    assert len(LEAVES) > 50


@pytest.mark.parametrize("leaf", LEAVES, ids=lambda leaf: leaf.key)
def test_every_config_value_has_a_description(leaf: object) -> None:
    assert leaf.text.strip(), f"{leaf.key}: no description= in cwrend_cli/config/schema.py"


@pytest.mark.parametrize("leaf", LEAVES, ids=lambda leaf: leaf.key)
def test_every_config_value_states_its_unit(leaf: object) -> None:
    assert leaf.unit is not None, (
        f"{leaf.key}: its description states no unit: end it with the unit in square "
        f"brackets, e.g. [km], [km/s²], [s], or [-] for a dimensionless number, a choice or "
        f"a name (the rule: docs/hooks/config_reference.py, UNIT_GROUP); got "
        f"{leaf.description!r}"
    )


def test_a_unit_is_told_from_other_brackets() -> None:
    leaf = _hook().Leaf(
        key="k",
        table="t",
        description="state [x, y, z] in [0, 1] [km, km/s]; more",
        type="float",
        default="0",
        bounds="",
    )
    assert leaf.unit == "km, km/s"
    assert leaf.text == "state [x, y, z] in [0, 1]; more"
    assert _hook().Leaf("k", "t", "a range [0, 1]", "float", "0", "").unit is None


def test_the_reference_shows_every_value_with_its_default_and_bounds() -> None:
    text = _hook().render_reference()
    rows = {line.split(" | ")[0].strip("| `"): line for line in text.splitlines()}
    for leaf in LEAVES:
        assert leaf.key in rows, leaf.key
    assert "`0.25`" in rows["schedule.beta"]  # the paper's value
    assert "[0, 1)" in rows["schedule.score_lowpass"]
    assert "(0, 1]" in rows["schedule.alpha_eps"]
    assert "each [-180, 180]" in rows["actuator.misalignment_deg"]
    assert "| km/s² |" in rows["scenario.u_max_km_s2"]


def test_the_reference_shows_every_bound_the_schema_enforces() -> None:
    """Each ge/gt/le/lt of a field (whoever adds it) reaches its row, in interval notation."""
    import annotated_types as at

    from cwrend_cli.config.schema import CwrendConfig

    rows = {leaf.key: leaf.bounds for leaf in LEAVES}
    checked = 0
    for section, info in CwrendConfig.model_fields.items():
        model = info.annotation
        if not isinstance(model, type) or not hasattr(model, "model_fields"):
            continue
        for name, field in model.model_fields.items():
            for rule in field.metadata:
                for attr, opener in (("ge", "["), ("gt", "("), ("le", "]"), ("lt", ")")):
                    value = getattr(rule, attr, None)
                    if isinstance(rule, (at.Ge, at.Gt, at.Le, at.Lt)) and value is not None:
                        shown = rows[f"{section}.{name}"]
                        number = _hook().fmt_bound(value)
                        assert number in shown, (section, name, attr, value, shown)
                        assert opener in shown or ("≥>≤<"["[(])".index(opener)] in shown)
                        checked += 1
    assert checked > 20


# ---------------------------------------------------------------------------
# The README: a front page, the two commands CI runs, no lab notebook
# ---------------------------------------------------------------------------

README = (REPO / "README.md").read_text(encoding="utf-8")
CI_LINES = [line.strip() for line in (REPO / ".ci/run").read_text(encoding="utf-8").splitlines()]
#: A commit hash: 7 to 40 hex digits with at least one letter and one digit, as a word.
COMMIT = re.compile(
    r"(?<![0-9A-Za-z])(?=[0-9a-f]*[a-f])(?=[0-9a-f]*[0-9])[0-9a-f]{7,40}(?![0-9A-Za-z])"
)
#: An issue reference: "issue 17", "issues 15", "#17", "item 3".
ISSUE = re.compile(r"\bissues?\s*#?\d+|(?<![\w&])#\d+\b|\bitems?\s+\d+", re.IGNORECASE)


def _commands() -> list[str]:
    return [block.strip() for block in re.findall(r"```bash\n(.*?)```", README, re.DOTALL)]


def test_the_readme_is_a_front_page_under_300_lines() -> None:
    assert len(README.splitlines()) < 300


def test_the_readme_names_no_commit() -> None:
    assert COMMIT.findall(README) == []


def test_the_readme_names_no_issue() -> None:
    assert ISSUE.findall(README) == []


def test_the_readme_opens_with_the_install_and_run_command() -> None:
    assert _commands()[0] == (
        "python3 -m venv .venv && . .venv/bin/activate && pip install . && "
        "cwrend ablate campaigns/paper.toml"
    )


def test_the_readme_test_command_is_what_ci_runs() -> None:
    install, test = _commands()[1].rsplit(" && ", 1)
    assert install == 'python3 -m venv .venv && . .venv/bin/activate && pip install ".[test]"'
    assert install in CI_LINES, ".ci/run installs otherwise than the README says"
    assert test == "pytest -q" and test in CI_LINES, ".ci/run tests otherwise than the README"


def test_the_readme_links_to_files_that_exist() -> None:
    targets = re.findall(r"\]\(([^)#\s]+)[^)]*\)", README)
    local = [t for t in targets if "://" not in t]
    assert len(local) > 10
    for target in local:
        assert (REPO / target).exists(), target


def test_the_readme_lists_every_page_of_the_manual() -> None:
    """The README's documentation list is the manual's table of contents: a page in the
    mkdocs nav that the README does not link is a page a reader of the front page never
    finds (the home page and the changelog, linked as CHANGELOG.md, aside)."""
    nav = (REPO / "mkdocs.yml").read_text(encoding="utf-8").split("\nnav:", 1)[1]
    pages = re.findall(r":\s*(\S+\.md)\s*$", nav, re.MULTILINE)
    assert len(pages) > 20
    linked = set(re.findall(r"\]\((docs/[^)#\s]+)", README))
    unlinked = [p for p in pages if f"docs/{p}" not in linked]
    missing = [p for p in unlinked if p not in ("index.md", "changelog.md")]
    assert missing == []


def test_shipped_files_cite_the_paper_not_the_teams_spec() -> None:
    """campaigns/paper.toml cited "SPEC §6", a document that is not shipped: what a user
    reads cites the paper (or the authors' code)."""
    shipped = [*REPO.glob("campaigns/*.toml"), *REPO.glob("docs/**/*.md"), REPO / "README.md"]
    citing = [p.relative_to(REPO) for p in shipped if "SPEC §" in p.read_text(encoding="utf-8")]
    assert citing == []
