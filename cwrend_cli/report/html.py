"""A self-contained ``report.html``: the text of ``report.md``, figures embedded, the config.

Renders the markdown that :func:`~cwrend_cli.report.markdown.report_md`
writes (headings, paragraphs, tables, images, ``code`` and **bold**), with
every figure embedded as a base64 PNG, followed by the resolved
configuration (TOML, as ``cwrend config show`` prints it and ``--config``
reads it back) and its hash, so the one file can be mailed. Its head says
what it is: the title (the results directory), when it was made, the cwrend
version and the config hash, then a table of contents of its sections
(issue 37 item 14).
"""

from __future__ import annotations

import base64
import html
import re
from collections.abc import Mapping

_STYLE = """
body { font-family: sans-serif; max-width: 1100px; margin: 2em auto; padding: 0 1em; }
table { border-collapse: collapse; margin: 1em 0; font-size: 0.9em; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.6em; text-align: left; }
th.num, td.num { text-align: right; }
th { background: #f0f4f8; }
img { max-width: 100%; }
pre { background: #f6f6f6; padding: 1em; overflow-x: auto; font-size: 0.85em; }
nav { background: #f6f8fa; padding: 0.5em 1em; margin: 1em 0; }
nav ul { margin: 0.25em 0; padding-left: 1.5em; }
.made { color: #555; }
"""


def _inline(text: str) -> str:
    """Escape ``text``; then ``code``, **bold** and a literal \\* as in report.md."""
    out = html.escape(text, quote=False)
    out = re.sub(r"`([^`]+)`", r"<code>\1</code>", out)
    out = re.sub(r"\*\*([^*]+)\*\*", r"<strong>\1</strong>", out)
    return out.replace("\\*", "*")


def _cells(line: str) -> list[str]:
    return [c.strip() for c in line.strip().strip("|").split("|")]


_NUMBER = re.compile(r"(\*\*)?[-+\u2212]?(\d|\.\d)|[\u2013\u2014-]$|nan$|inf$")
"""A cell that reads as a number (``12.3``, ``-4e-05``, ``0.84 [0.82, 0.86]``) or as
the dash of a missing value: right-aligned, so the digits line up."""


def _numeric_columns(rows: list[list[str]], width: int) -> list[bool]:
    """For each column: True when every non-empty body cell reads as a number."""
    return [
        all(_NUMBER.match(r[j]) for r in rows if j < len(r) and r[j])
        and any(j < len(r) and r[j] for r in rows)
        for j in range(width)
    ]


def _table(lines: list[str]) -> str:
    """A markdown table as HTML: text columns aligned left, number columns right."""
    header, *body = [ln for ln in lines if not re.fullmatch(r"\|[-:|]+\|", ln.strip())]
    head_cells = _cells(header)
    rows = [_cells(r) for r in body]
    numeric = _numeric_columns(rows, len(head_cells))

    def cell(tag: str, j: int, text: str) -> str:
        kind = ' class="num"' if j < len(numeric) and numeric[j] else ""
        return f"<{tag}{kind}>{_inline(text)}</{tag}>"

    def row(tag: str, cells: list[str]) -> str:
        return "<tr>" + "".join(cell(tag, j, c) for j, c in enumerate(cells)) + "</tr>"

    out = ["<table>", row("th", head_cells), *(row("td", r) for r in rows)]
    return "\n".join([*out, "</table>"])


def _image(alt: str, file: str, images: Mapping[str, bytes]) -> str:
    data = images.get(file)
    if data is None:
        return f"<p>(figure {html.escape(file)} missing)</p>"
    b64 = base64.b64encode(data).decode("ascii")
    return f'<img alt="{html.escape(alt)}" src="data:image/png;base64,{b64}">'


def _anchor(text: str, taken: set[str]) -> str:
    """An id for a heading: its words, lower case, joined by ``-``; unique in the page."""
    base = re.sub(r"[^\w]+", "-", text.lower()).strip("-") or "section"
    anchor, k = base, 2
    while anchor in taken:
        anchor, k = f"{base}-{k}", k + 1
    taken.add(anchor)
    return anchor


def _contents(headings: list[tuple[int, str, str]]) -> str:
    """The table of contents: the level-2 sections, their level-3 ones nested."""
    out = ["<nav><strong>Contents</strong>", "<ul>"]
    open_sub = False
    for level, anchor, text in headings:
        item = f'<li><a href="#{anchor}">{text}</a>'
        if level == 2:
            if open_sub:
                out.append("</ul></li>")
                open_sub = False
            out.append(item)
        elif level == 3:
            if not open_sub:
                out.append("<ul>")
                open_sub = True
            out.append(item + "</li>")
    if open_sub:
        out.append("</ul></li>")
    return "\n".join([*out, "</ul></nav>"])


def report_html(
    markdown: str,
    images: Mapping[str, bytes],
    config_toml: str | None,
    config_hash: str,
    *,
    title: str,
    made: str,
    version: str,
) -> str:
    """The HTML page of ``markdown`` with ``images`` (file name → PNG bytes) embedded.

    ``title``: what the report is of (e.g. the results directory's name);
    ``made``: when (e.g. ``2026-12-02 09:14 UTC``); ``version``: cwrend's. The
    head of the page gives them with the config hash, then the contents of
    the level-2 and level-3 sections; the configuration ends the page.
    """
    body: list[str] = []
    headings: list[tuple[int, str, str]] = []
    taken: set[str] = set()
    lines = markdown.splitlines()
    i = 0
    while i < len(lines):
        line = lines[i]
        if line.startswith("|"):
            block = []
            while i < len(lines) and lines[i].startswith("|"):
                block.append(lines[i])
                i += 1
            body.append(_table(block))
            continue
        heading = re.match(r"(#{1,6}) (.*)", line)
        image = re.fullmatch(r"!\[([^\]]*)\]\(([^)]+)\)", line.strip())
        if heading and len(heading.group(1)) == 1:  # the page's own title replaces it
            pass
        elif heading:
            level = len(heading.group(1))
            text = _inline(heading.group(2))
            anchor = _anchor(heading.group(2), taken)
            headings.append((level, anchor, text))
            body.append(f'<h{level} id="{anchor}">{text}</h{level}>')
        elif image:
            body.append(_image(image.group(1), image.group(2), images))
        elif line.strip():
            body.append(f"<p>{_inline(line)}</p>")
        i += 1
    anchor = _anchor("configuration", taken)
    headings.append((2, anchor, "Configuration"))
    body.append(f'<h2 id="{anchor}">Configuration</h2>')
    hash_html = f"<code>{html.escape(config_hash or '(none)')}</code>"
    body.append(f"<p>Config hash {hash_html}; the resolved configuration as TOML:</p>")
    config = config_toml if config_toml is not None else "(no configuration stored)"
    body.append(f"<pre>{html.escape(config, quote=False)}</pre>")
    name = html.escape(f"cwrend report · {title}")
    head = [
        f"<h1>{name}</h1>",
        f'<p class="made">Made {html.escape(made)} by cwrend {html.escape(version)}; '
        f"config hash {hash_html}.</p>",
        _contents(headings),
    ]
    return "\n".join(
        [
            "<!DOCTYPE html>",
            f'<html lang="en"><head><meta charset="utf-8"><title>{name}</title>',
            f"<style>{_STYLE}</style></head><body>",
            *head,
            *body,
            "</body></html>",
            "",
        ]
    )
