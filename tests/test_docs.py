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


# ---------------------------------------------------------------------------
# The guides against the tool: the options they give, the pages they link
# ---------------------------------------------------------------------------

#: The pages a new user follows: the front page, the tour, the manual's home and the guides.
USER_PAGES = [
    REPO / "README.md",
    REPO / "docs/getting-started.md",
    REPO / "docs/index.md",
    *sorted((REPO / "docs/guide").glob("*.md")),
]
#: An option as written on a command line: ``--seeds``, ``-n`` (not ``-1`` or ``a-b``).
OPTION = re.compile(r"(?<![\w-])(--?[A-Za-z][\w-]*)")


def _command_options() -> dict[str, set[str]]:
    """Every command's options by its name as typed (``ablate``, ``config show``)."""
    from typer.main import get_command

    from cwrend_cli.cli import app

    def options(command: object) -> set[str]:
        names = {"--help"}
        for param in getattr(command, "params", []):
            names |= set(param.opts) | set(getattr(param, "secondary_opts", []))
        return names

    found: dict[str, set[str]] = {}
    for name, command in get_command(app).commands.items():  # type: ignore[attr-defined]
        found[name] = options(command)
        for sub, subcommand in getattr(command, "commands", {}).items():
            found[f"{name} {sub}"] = options(subcommand)
    return found


def _command_lines(text: str) -> list[str]:
    """Each ``cwrend …`` invocation of a page: lines of its bash blocks (continuations
    joined) and inline code spans, split at ``&&`` and ``;`` (not at ``|``, which a
    synopsis uses between alternatives: ``[--seeds N | --seed-list 0,5,9]``)."""
    blocks = re.findall(r"```bash\n(.*?)```", text, re.DOTALL)
    lines = [line for block in blocks for line in block.replace("\\\n", " ").splitlines()]
    prose = re.sub(r"```.*?```", "", text, flags=re.DOTALL).replace("\n", " ")
    lines += re.findall(r"`(cwrend [^`]*)`", prose)
    parts = (part.split(" #")[0].strip() for line in lines for part in re.split(r"&&|;", line))
    return [part for part in parts if part.startswith("cwrend ")]


def _options_not_of_their_command() -> list[str]:
    """``page: what is wrong: line`` for each command line naming an option (or a command)
    that cwrend does not have; ``cwrend run|ablate … --format`` is checked for each."""
    commands = _command_options()
    wrong = []
    for page in USER_PAGES:
        for line in _command_lines(page.read_text(encoding="utf-8")):
            words = [*line.split()[1:], "", ""]
            name = " ".join(words[:2]) if " ".join(words[:2]) in commands else words[0]
            if not name.islower():  # a placeholder (COMMAND) is not a command
                continue
            unknown = [n for n in name.split("|") if n not in commands]
            if unknown:
                wrong.append(f"{page.name}: no command 'cwrend {unknown[0]}': {line}")
                continue
            options = OPTION.findall(line.split(name, 1)[1])
            wrong += [
                f"{page.name}: cwrend {n} has no option {option}: {line}"
                for n in name.split("|")
                for option in options
                if option not in commands[n]
            ]
    return wrong


def test_every_option_the_guides_give_a_command_is_one_of_its_options() -> None:
    """A command line in the README, the tour or a guide (a bash block or an inline
    ``cwrend …``) names only options that command has (``cwrend COMMAND --help``)."""
    assert _options_not_of_their_command() == []


def _heading_anchors(page: Path) -> set[str]:
    """The anchors MkDocs gives the headings of a page (Python-Markdown's toc slugs,
    a repeated heading suffixed ``_1``, ``_2``, …)."""
    from markdown.extensions.toc import slugify

    text = re.sub(r"```.*?```", "", page.read_text(encoding="utf-8"), flags=re.DOTALL)
    anchors: set[str] = set()
    for heading in re.findall(r"^#{1,6}\s+(.*?)\s*#*\s*$", text, re.MULTILINE):
        plain = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", heading).replace("`", "")
        slug, n = slugify(plain, "-"), 0
        while (slug if n == 0 else f"{slug}_{n}") in anchors:
            n += 1
        anchors.add(slug if n == 0 else f"{slug}_{n}")
    return anchors


def _broken_links() -> list[str]:
    pages = [REPO / "README.md", *sorted((REPO / "docs").rglob("*.md"))]
    broken = []
    for page in pages:
        text = re.sub(r"```.*?```", "", page.read_text(encoding="utf-8"), flags=re.DOTALL)
        text = re.sub(r"`[^`\n]*`", "", text)
        for target in re.findall(r"\]\(([^)\s]+)\)", text):
            if "://" in target or target.startswith("mailto:"):
                continue
            path, _, anchor = target.partition("#")
            linked = (page.parent / path).resolve() if path else page
            where = f"{page.relative_to(REPO)}: {target}"
            if not linked.exists():
                broken.append(f"{where} (no such file)")
            elif anchor and linked.suffix == ".md" and anchor not in _heading_anchors(linked):
                broken.append(f"{where} (no such heading)")
    return broken


def test_every_link_of_the_manual_reaches_a_page_and_its_heading() -> None:
    """A link between pages of the manual (or from the README) names a file that exists
    and, after ``#``, a heading of it: a renamed heading breaks no link silently."""
    assert _broken_links() == []
