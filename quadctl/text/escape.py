"""One escaping per output format: a string (from a config, a file name, a command line) as it must be
written in each format quadctl writes.

- :func:`html_text`: HTML text and attribute values (``&``, ``<``, ``>``, both quotes);
- :func:`markdown_text`: Markdown text, every character that could start markup escaped;
- :func:`markdown_fence`: a code block's fence, longer than any run of backticks in it;
- :func:`c_comment`: text inside a C comment (``*/`` cannot close it);
- :func:`c_identifier`, :func:`matlab_field`: names that must already be identifiers (refused, never mangled).

JSON needs none: :func:`json.dumps` escapes every string it writes.

Examples
--------
>>> markdown_text("<img src=x onerror=alert(1)>")
'&lt;img src=x onerror=alert(1)>'
>>> markdown_text("Hover at 1 m altitude, report weights")
'Hover at 1 m altitude, report weights'
>>> markdown_fence("a\\n`````\\nb")
'``````'
>>> c_comment("a */ b")
'a *\\\\/ b'
"""

from __future__ import annotations

import html
import re

html_text = html.escape
"""HTML text or a double- or single-quoted attribute value (:func:`html.escape`, ``quote=True``)."""

_MD_ALWAYS = re.compile(r"[\\`~]")
"""Escaped wherever they stand: backslash, code spans, strikethrough (GitHub)."""
_MD_EMPHASIS = re.compile(r"\*+|_+")
"""Runs of ``*`` or ``_``: emphasis when they open or close one (:func:`_delimiters`)."""
_MD_TAG = re.compile(r"<(?=[A-Za-z/!?])")
"""``<`` starts an HTML tag, comment or autolink only before a letter, ``/``, ``!`` or ``?``."""
_MD_ENTITY = re.compile(r"&(?=#?[A-Za-z0-9]+;)")
"""``&`` starts a character reference only before ``name;`` or ``#digits;``."""
_MD_LINK = re.compile(r"\](?=[(\[])|!(?=\[)|\[(?=\^)")
"""``](`` and ``][`` make links; ``![`` an image; ``[^`` a footnote (a line that starts ``[x]:``, a
link definition, is :data:`_MD_BLOCK_START`'s)."""
_MD_BRACKET = re.compile(r"[\[\]]|!(?=\[)")
"""Inside a link's or an image's text every bracket is escaped: an unmatched one would pair with the
enclosing markup's own."""
_MD_BLOCK_START = re.compile(r"^(#{1,6}(?=\s|$)|>|[-+](?=\s|$|-)|\d{1,9}[.)](?=\s|$)|\[(?=[^\]]*\]:))")
"""What makes a paragraph's first line a heading, a quote, a list item, a thematic break or a link
definition (``[x]: url``)."""
_MD_NEWLINES = re.compile(r"\s*[\r\n]+\s*")


def markdown_text(text: str, *, block: bool = True, wrapped: bool = False, link: bool = False) -> str:
    """``text`` as literal Markdown text on one line.

    Line breaks become spaces (a config's line cannot start a block); every character that could
    make markup is escaped with a backslash or as a character reference. Text without any is
    returned unchanged. ``block``: the text starts a line (a paragraph, a heading's text, a list
    item's), where ``# ``, ``> ``, ``- ``, ``1. `` and leading spaces make blocks too; False inside
    a line (a table cell, a link's text, an emphasis). ``wrapped``: the text stands inside markup
    of its own (``**title**``, ``*caption*``), whose delimiters a lone ``*`` in it could close.
    ``link``: the text is a link's or an image's ``[text]``, which any unmatched bracket in it would
    end early (every bracket is escaped; implies ``wrapped``).

    Examples
    --------
    >>> markdown_text("**bold** [link](http://x) `code` # not a heading")
    '\\\\*\\\\*bold\\\\*\\\\* [link\\\\](http://x) \\\\`code\\\\` # not a heading'
    >>> markdown_text("# heading")
    '\\\\# heading'
    """
    text = _MD_NEWLINES.sub(" ", str(text))
    text = _MD_ENTITY.sub("&amp;", text)
    text = _MD_ALWAYS.sub(lambda m: "\\" + m.group(0), text)
    text = _escape_emphasis(text, wrapped or link)
    text = _MD_TAG.sub("&lt;", text)
    text = (_MD_BRACKET if link else _MD_LINK).sub(lambda m: "\\" + m.group(0), text)
    if not block:
        return text
    return _MD_BLOCK_START.sub(_escape_block_start, text.lstrip())


def _escape_emphasis(text: str, wrapped: bool) -> str:
    """Backslash every ``*`` and ``_`` run that could open or close emphasis.

    A run between spaces (``a * b``) never can, nor ``_`` inside a word (``x_ref``); the rest can,
    but emphasis needs two of them in the same text: a lone one (``guidance*``) stays as written
    unless the text is ``wrapped`` in delimiters it could pair with.
    """
    runs = [m for m in _MD_EMPHASIS.finditer(text) if _can_delimit(text, m)]
    if not runs or (len(runs) == 1 and not wrapped):
        return text
    out, last = [], 0
    for m in runs:
        out += [text[last:m.start()], "".join("\\" + c for c in m.group(0))]
        last = m.end()
    return "".join(out) + text[last:]


def _can_delimit(text: str, run: re.Match) -> bool:
    before = text[run.start() - 1] if run.start() > 0 else " "
    after = text[run.end()] if run.end() < len(text) else " "
    if before.isspace() and after.isspace():
        return False
    return not (run.group(0)[0] == "_" and before.isalnum() and after.isalnum())


def _escape_block_start(match: re.Match) -> str:
    mark = match.group(0)
    return mark[:-1] + "\\" + mark[-1] if mark[0].isdigit() else "\\" + mark


def markdown_fence(text: str) -> str:
    """A backtick fence for a code block holding ``text``: at least three backticks, and longer
    than the longest run of backticks in ``text`` (CommonMark closes a fence only with one at least
    as long as the opening)."""
    longest = max((len(run) for run in re.findall(r"`+", text)), default=0)
    return "`" * max(3, longest + 1)


def c_comment(text: str) -> str:
    """``text`` inside a C block comment: ``*/`` (which would end it) becomes ``*\\/``; a ``/*``
    is harmless inside a comment but is split too, so no compiler warns of a nested comment."""
    return str(text).replace("*/", "*\\/").replace("/*", "/\\*")


_C_IDENTIFIER = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_MATLAB_FIELD = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,62}")


def c_identifier(name: str) -> str:
    """``name``, checked to be a C identifier; ValueError otherwise (names are validated at load,
    :data:`quadctl.config.SUBSYSTEM_NAME_PATTERN`: one that is not is a bug, never mangled)."""
    if not _C_IDENTIFIER.fullmatch(name):
        raise ValueError(f"{name!r} is not a C identifier")
    return name


def matlab_field(name: str) -> str:
    """``name``, checked to be a MATLAB struct field name (a letter, then up to 62 letters, digits
    or ``_``); ValueError otherwise (:func:`scipy.io.savemat` would drop the field with a warning)."""
    if not _MATLAB_FIELD.fullmatch(name):
        raise ValueError(f"{name!r} is not a MATLAB field name")
    return name
