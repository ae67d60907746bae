"""A self-contained ``report.html``: the text of ``report.md``, figures embedded, the config.

Renders the markdown that :func:`~cwrend_cli.report.markdown.report_md`
writes (headings, paragraphs, tables, images, ``code`` and **bold**), with
every figure embedded as a base64 PNG, followed by the resolved
configuration (JSON) and its hash, so the one file can be mailed.
"""

from __future__ import annotations

import base64
import html
import re
from collections.abc import Mapping

_STYLE = """
body { font-family: sans-serif; max-width: 1100px; margin: 2em auto; padding: 0 1em; }
table { border-collapse: collapse; margin: 1em 0; font-size: 0.9em; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.6em; text-align: right; }
th:first-child, td:first-child { text-align: left; }
th { background: #f0f4f8; }
img { max-width: 100%; }
pre { background: #f6f6f6; padding: 1em; overflow-x: auto; font-size: 0.85em; }
"""


def _inline(text: str) -> str:
    """Escape ``text``; then ``code``, **bold** and a literal \\* as in report.md."""
    out = html.escape(text, quote=False)
    out = re.sub(r"`([^`]+)`", r"<code>\1</code>", out)
    out = re.sub(r"\*\*([^*]+)\*\*", r"<strong>\1</strong>", out)
    return out.replace("\\*", "*")


def _cells(line: str) -> list[str]:
    return [c.strip() for c in line.strip().strip("|").split("|")]


def _table(lines: list[str]) -> str:
    header, *rows = [ln for ln in lines if not re.fullmatch(r"\|[-|]+\|", ln.strip())]
    out = ["<table>", "<tr>" + "".join(f"<th>{_inline(c)}</th>" for c in _cells(header)) + "</tr>"]
    out += ["<tr>" + "".join(f"<td>{_inline(c)}</td>" for c in _cells(r)) + "</tr>" for r in rows]
    return "\n".join([*out, "</table>"])


def _image(alt: str, file: str, images: Mapping[str, bytes]) -> str:
    data = images.get(file)
    if data is None:
        return f"<p>(figure {html.escape(file)} missing)</p>"
    b64 = base64.b64encode(data).decode("ascii")
    return f'<img alt="{html.escape(alt)}" src="data:image/png;base64,{b64}">'


def report_html(
    markdown: str, images: Mapping[str, bytes], config_json: str | None, config_hash: str
) -> str:
    """The HTML page of ``markdown`` with ``images`` (file name → PNG bytes) embedded."""
    body: list[str] = []
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
        if heading:
            level = len(heading.group(1))
            body.append(f"<h{level}>{_inline(heading.group(2))}</h{level}>")
        elif image:
            body.append(_image(image.group(1), image.group(2), images))
        elif line.strip():
            body.append(f"<p>{_inline(line)}</p>")
        i += 1
    body.append("<h2>Configuration</h2>")
    body.append(f"<p>Config hash <code>{html.escape(config_hash or '(none)')}</code></p>")
    config = config_json if config_json is not None else "(no configuration stored)"
    body.append(f"<pre>{html.escape(config, quote=False)}</pre>")
    return "\n".join(
        [
            "<!DOCTYPE html>",
            '<html lang="en"><head><meta charset="utf-8"><title>cwrend report</title>',
            f"<style>{_STYLE}</style></head><body>",
            *body,
            "</body></html>",
            "",
        ]
    )
