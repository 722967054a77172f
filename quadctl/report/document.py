"""The report as data (sections of paragraphs, tables, code and figures), and its two renderings.

One document, two renderers: :func:`to_html` (one self-contained file: CSS inline, figures as
``data:`` URIs, no script, nothing fetched) and :func:`to_markdown` (figures as files beside it).
The page layout and the style are package files (``quadctl/report/templates``), filled with
:class:`string.Template`.
"""

from __future__ import annotations

import base64
import re
from dataclasses import dataclass, field
from importlib import resources
from string import Template

from quadctl.present.cells import Table as Table  # the presented table: rows the terminal shows too
from quadctl.text.escape import html_text, markdown_fence, markdown_text


@dataclass(frozen=True)
class Text:
    """A paragraph. ``kind``: ``""``, ``"ok"``, ``"warning"`` or ``"fail"`` (a verdict, coloured)."""

    text: str
    kind: str = ""


@dataclass(frozen=True)
class Items:
    """A bulleted list."""

    items: tuple[str, ...]


@dataclass(frozen=True)
class Code:
    """Preformatted text (a YAML config) under a caption."""

    caption: str
    text: str


@dataclass(frozen=True)
class Figure:
    """A PNG figure; ``name`` is its file stem beside the Markdown report."""

    name: str
    caption: str
    png: bytes = field(repr=False)

    @property
    def file(self) -> str:
        return f"{self.name}.png"


@dataclass(frozen=True)
class Row:
    """Blocks side by side where the page is wide enough (one after the other in Markdown)."""

    blocks: tuple


@dataclass(frozen=True)
class Section:
    id: str
    title: str
    blocks: tuple = ()


@dataclass(frozen=True)
class Document:
    """The whole report: a title, one status line, the sections in order."""

    title: str
    subtitle: str
    status: Text
    sections: tuple[Section, ...]
    generator: str

    @property
    def figures(self) -> list[Figure]:
        return [b for s in self.sections for b in _flat(s.blocks) if isinstance(b, Figure)]


def _flat(blocks) -> list:
    return [inner for b in blocks for inner in (_flat(b.blocks) if isinstance(b, Row) else [b])]


def _template(name: str) -> str:
    return (resources.files("quadctl.report") / "templates" / name).read_text(encoding="utf-8")


# -- HTML ---------------------------------------------------------------------------------

_e = html_text


def _html_block(block) -> str:
    if isinstance(block, Row):
        return '<div class="row">' + "".join(_html_block(b) for b in block.blocks) + "</div>"
    if isinstance(block, Text):
        cls = f' class="{block.kind}"' if block.kind else ""
        return f"<p{cls}>{_e(block.text)}</p>"
    if isinstance(block, Items):
        return "<ul>" + "".join(f"<li>{_e(item)}</li>" for item in block.items) + "</ul>"
    if isinstance(block, Code):
        return (f'<figure class="code"><figcaption>{_e(block.caption)}</figcaption>'
                f"<pre>{_e(block.text)}</pre></figure>")
    if isinstance(block, Table):
        align = block.alignment()
        head = "".join(f'<th class="{a}">{_e(c)}</th>' for c, a in zip(block.columns, align))
        body = "".join("<tr>" + "".join(f'<td class="{a}">{_e(c)}</td>' for c, a in zip(row, align)) + "</tr>"
                       for row in block.rows)
        note = f'<p class="caption">{_e(block.caption)}</p>' if block.caption else ""
        return (f'<div class="table"><p class="title">{_e(block.title)}</p><table id="{_e(block.id)}">'
                f"<thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>{note}</div>")
    if isinstance(block, Figure):
        data = base64.b64encode(block.png).decode("ascii")
        return (f'<figure class="plot"><img alt="{_e(block.caption)}" src="data:image/png;base64,{data}">'
                f"<figcaption>{_e(block.caption)}</figcaption></figure>")
    raise TypeError(f"no HTML for {type(block).__name__}")


def to_html(doc: Document) -> str:
    """One self-contained HTML page: no external file, no network, no script."""
    toc = "".join(f'<li><a href="#{_e(s.id)}">{_e(s.title)}</a></li>' for s in doc.sections)
    body = "\n".join(f'<section id="{_e(s.id)}"><h2>{_e(s.title)}</h2>\n'
                     + "\n".join(_html_block(b) for b in s.blocks) + "</section>" for s in doc.sections)
    return Template(_template("report.html")).substitute(
        title=_e(doc.title), subtitle=_e(doc.subtitle), style=_template("report.css"),
        status=_html_block(doc.status), toc=toc, body=body, generator=_e(doc.generator))


# -- Markdown -----------------------------------------------------------------------------
# Every text goes through markdown_text (quadctl's own and a config's alike: a name, a description, a
# file name), code through a fence longer than any run of backticks in it.

_md = markdown_text


def _md_inline(text: str, wrapped: bool = False, link: bool = False) -> str:
    return markdown_text(text, block=False, wrapped=wrapped, link=link)


def _md_cell(text: str) -> str:
    return _md_inline(text).replace("|", "\\|") or " "


def _md_block(block) -> str:
    if isinstance(block, Row):
        return "\n\n".join(_md_block(b) for b in block.blocks)
    if isinstance(block, Text):
        mark = {"ok": "✓ ", "warning": "⚠ ", "fail": "✗ "}.get(block.kind, "")
        return f"{mark}{_md(block.text)}"
    if isinstance(block, Items):
        return "\n".join(f"- {_md(item)}" for item in block.items)
    if isinstance(block, Code):
        fence = markdown_fence(block.text)
        return f"{_md(block.caption)}:\n\n{fence}yaml\n{block.text.rstrip()}\n{fence}"
    if isinstance(block, Table):
        rule = {"l": "---", "w": "---", "r": "---:"}
        lines = [f"**{_md_inline(block.title, wrapped=True)}**", "",
                 "| " + " | ".join(_md_cell(c) for c in block.columns) + " |",
                 "|" + "|".join(rule[a] for a in block.alignment()) + "|"]
        lines += ["| " + " | ".join(_md_cell(c) for c in row) + " |" for row in block.rows]
        if block.caption:
            lines += ["", f"*{_md_inline(block.caption, wrapped=True)}*"]
        return "\n".join(lines)
    if isinstance(block, Figure):
        return f"![{_md_inline(block.caption, link=True)}]({block.file})"
    raise TypeError(f"no Markdown for {type(block).__name__}")


_FIGURE_LINE = re.compile(r"^!\[.*\]\((?P<file>[A-Za-z0-9_][A-Za-z0-9_.+-]*\.png)\)$", re.MULTILINE)


def figure_files(markdown: str) -> set[str]:
    r"""The figure files a Markdown report made by :func:`to_markdown` shows (its ``![...](x.png)``
    lines): what a later report may remove, as the files an earlier one wrote.

    >>> sorted(figure_files("![roll step](roll.png)\ntext ![x](y.png) inline"))
    ['roll.png']
    """
    return {m["file"] for m in _FIGURE_LINE.finditer(markdown)}


def to_markdown(doc: Document) -> str:
    """The same report in Markdown; its figures are the files ``Figure.file`` beside it."""
    toc = "\n".join(f"- [{_md_inline(s.title, link=True)}](#{_e(s.id)})" for s in doc.sections)
    body = "\n\n".join(f'<a id="{_e(s.id)}"></a>\n\n## {_md(s.title)}\n\n'
                       + "\n\n".join(_md_block(b) for b in s.blocks) for s in doc.sections)
    return Template(_template("report.md")).substitute(
        title=_md(doc.title), subtitle=_md(doc.subtitle), status=_md_block(doc.status), toc=toc, body=body,
        generator=_md_inline(doc.generator, wrapped=True))
