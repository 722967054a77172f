"""A string from a config (its description, its text, a file name) lands literally in every format
quadctl writes: Markdown, HTML, a C comment, a C identifier, JSON, a ``.mat`` field.

The Markdown and HTML are checked by rendering them with an independent parser (markdown-it-py's
CommonMark, Python's ``html.parser``), not by looking for the escapes quadctl writes.
"""

from __future__ import annotations

import html
import json
from dataclasses import replace
from html.parser import HTMLParser

import pytest

from quadctl import artifacts
from quadctl.report.document import Code, Document, Figure, Items, Section, Table, Text, to_html, to_markdown
from quadctl.text import escape

HOSTILE = [
    "<img src=x onerror=alert(1)>",
    "**bold** _it_ `code` ~~gone~~ [link](http://x.y) ![i](j.png) <b>b</b> &amp; \\* # h",
    "# heading\n- item\n> quote\n1. first\n\n<script>alert(1)</script>",
    "a | b | c */ d /* e",
    "[x]: http://evil.example",
]


def _doc(text: str, code: str = "name: x\n") -> Document:
    return Document(
        title=f"quadctl report: {text}", subtitle=text, status=Text(text, "fail"), generator=text,
        sections=(Section("config", text, (
            Text(text), Items((text, "plain")), Code(text, code),
            Table("t", text, (text, "b"), ((text, "1"),), caption=text),
            Figure("roll", text, b"png"))),))


def _markdown_html(markdown: str) -> str:
    from markdown_it import MarkdownIt

    return MarkdownIt("commonmark").enable("table").enable("strikethrough").render(markdown)


class _Tags(HTMLParser):
    def __init__(self, page: str):
        super().__init__()
        self.tags, self.text, self.pres, self._in_pre = [], [], [], False
        self.feed(page)

    def handle_starttag(self, tag, attrs):
        self.tags.append(tag)
        self._in_pre = self._in_pre or tag in ("pre", "code")
        if tag == "pre":
            self.pres.append("")

    def handle_endtag(self, tag):
        if tag == "pre":
            self._in_pre = False

    def handle_data(self, data):
        self.text.append(data)
        if self._in_pre and self.pres:
            self.pres[-1] += data


ALLOWED_MARKDOWN_TAGS = {"h1", "h2", "p", "ul", "li", "a", "pre", "code", "strong", "em", "table", "thead",
                         "tbody", "tr", "th", "td", "img", "hr"}
"""What the report's own Markdown makes (headings, the TOC, bold titles, italic captions, figures)."""


@pytest.mark.parametrize("text", HOSTILE)
def test_config_text_stays_text_in_the_markdown_report(text):
    page = _markdown_html(to_markdown(_doc(text)))
    tags = _Tags(page)
    assert set(tags.tags) <= ALLOWED_MARKDOWN_TAGS, set(tags.tags) - ALLOWED_MARKDOWN_TAGS
    one_line = " ".join(text.split())
    rendered = html.unescape(page)
    assert one_line in " ".join(rendered.split())  # every character survives, as text
    assert tags.tags.count("img") == 1 and tags.tags.count("h1") == 1 and tags.tags.count("h2") == 1
    assert "<script" not in page and "<b>" not in page and "onerror" not in "".join(tags.tags)


@pytest.mark.parametrize("text", HOSTILE)
def test_a_paragraph_of_config_text_renders_whole(text):
    """The description alone on its line (the subtitle): no block (heading, list, link definition) starts."""
    page = _markdown_html(to_markdown(Document(title="t", subtitle=text, status=Text("ok"), sections=(),
                                               generator="g")))
    paragraphs = [html.unescape(p) for p in page.split("<p>")[1:]]
    assert paragraphs[0].startswith(" ".join(text.split()) + "</p>"), page


@pytest.mark.parametrize("fence", ["```", "````", "`````", "``````````"])
def test_a_config_with_backtick_runs_stays_inside_its_code_block(fence):
    code = f"name: x\n{fence}\n# not a heading\n<img src=x onerror=alert(1)>\ndescription: after\n"
    page = _markdown_html(to_markdown(_doc("plain", code)))
    tags = _Tags(page)
    assert tags.pres == [code.rstrip() + "\n"]  # the whole text, in one block
    assert tags.tags.count("img") == 1  # the figure's only


def test_markdown_text_without_markup_is_unchanged():
    """The reports of ordinary configs read (and are) as before: nothing to escape, nothing escaped."""
    for text in ("Hover at 1 m altitude, report weights", "x_ref(t) = x_trim + x_rate t", "a * b", "-0.5",
                 "1.5 m", "3 of 4 loops", "guidance*", "[T, A, E, R]", "|z| < 1 & stable"):
        assert escape.markdown_text(text) == text


def test_markdown_fence_is_longer_than_any_backtick_run():
    for text in ("", "a", "``", "```", "a ````` b ``` c"):
        fence = escape.markdown_fence(text)
        assert len(fence) >= 3 and fence not in text


@pytest.mark.parametrize("text", HOSTILE)
def test_config_text_stays_text_in_the_html_report(text):
    page = to_html(_doc(text, code=f"```\n{text}\n"))
    tags = _Tags(page)
    assert "script" not in tags.tags and "b" not in tags.tags
    assert tags.tags.count("img") == 1  # the figure's only
    assert text in "".join(tags.text)
    assert f"```\n{text}" in tags.pres[0]


def test_a_c_comment_cannot_be_closed_from_the_text():
    text = "a */ int evil; /* b"
    comment = f"/* {escape.c_comment(text)} */"
    assert comment.count("*/") == 1 and comment.endswith("*/") and comment.count("/*") == 1


@pytest.fixture(scope="module")
def exported():
    from quadctl import config, export
    from quadctl.setup import setup_of

    cfg = config.load("crazyflie")
    return export.prepare(setup_of(cfg), config_hash=cfg.digest())


def test_the_c_export_escapes_the_config_name_in_its_comments(exported, tmp_path):
    from quadctl.export import c as cexport
    from quadctl.native.compile import find_compiler

    hostile = replace(exported, setup=replace(exported.setup, name="x */ int evil; /*"))
    files = cexport.sources(hostile)
    for text in files.values():
        assert '"x *\\/ int evil; /\\*"' in text and '"x */' not in text
    compiler = find_compiler()
    if compiler is None:
        pytest.skip("no C compiler")
    import subprocess

    for name, text in files.items():
        (tmp_path / name).write_text(text)
    res = subprocess.run([compiler, "-std=c99", "-Wall", "-Wextra", "-pedantic", "-Werror", "-c",
                          str(tmp_path / cexport.SOURCE), "-o", str(tmp_path / "x.o")], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr


@pytest.mark.parametrize("name", ["roll axis", "1st", "a-b", "é", "", "x" * 64])
def test_names_that_are_no_c_identifier_or_matlab_field_are_refused(name):
    import re

    if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", name):
        with pytest.raises(ValueError, match="is not a C identifier"):
            escape.c_identifier(name)
    with pytest.raises(ValueError, match="is not a MATLAB field name"):
        escape.matlab_field(name)


def test_a_subsystem_name_is_a_field_of_the_mat_file(exported, tmp_path):
    """The subsystems struct keeps every subsystem (scipy.io.loadmat reads them back by name)."""
    import io

    from scipy.io import loadmat

    from quadctl.export import data

    buf = io.BytesIO()
    data.write_mat(buf, exported)
    buf.seek(0)
    subs = loadmat(buf)["subsystems"]
    assert set(subs.dtype.names) == {s.name for s in exported.design.subsystems}


@pytest.mark.parametrize("text", [*HOSTILE, 'quote " backslash \\ newline \n tab \t nul \x00 line \u2028 é'])
def test_config_text_round_trips_through_json(tmp_path, text):
    path = artifacts.write_json(tmp_path / "trim.json", {"description": text, text: 1})
    raw = path.read_bytes()
    assert raw.isascii()  # every non-ASCII character escaped: no encoding question
    assert json.loads(raw) == {"description": text, text: 1}
