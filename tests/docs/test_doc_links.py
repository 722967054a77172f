"""Every link of the README and of the site's pages (docs/**/*.md) finds its target in the repository:
a relative path to a file of the checkout (never outside it: a clone has nothing beside it), a
``#anchor`` to a heading of the target page (GitHub's heading anchors); an external ``http(s)`` link
is only checked for syntax, never fetched."""

from __future__ import annotations

import re
import unicodedata
from pathlib import Path
from urllib.parse import unquote, urlsplit

import pytest
from _paths import ROOT

PAGES = [ROOT / "README.md", *sorted(p for p in (ROOT / "docs").rglob("*.md") if "_build" not in p.parts)]

FENCE = re.compile(r"^(```|~~~).*?^\1[^\n]*$", re.S | re.M)
CODE_SPAN = re.compile(r"(`+)(?:(?!\1).)+?\1", re.S)
LINK = re.compile(r"!?\[(?:[^\[\]]|\[[^\]]*\])*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
"""Inline links and images: ``[text](target "title")``, ``![alt](target)``."""
REFERENCE = re.compile(r"^\s{0,3}\[[^\]]+\]:\s*<?(\S+?)>?(?:\s+\"[^\"]*\")?\s*$", re.M)
"""Reference definitions: ``[label]: target``."""
AUTOLINK = re.compile(r"<((?:https?|mailto):[^>\s]+)>")
HEADING = re.compile(r"^\s{0,3}(#{1,6})\s+(.*?)\s*#*\s*$", re.M)


def prose(text: str) -> str:
    """``text`` without fenced code blocks and code spans (a link there is code, not a link)."""
    return CODE_SPAN.sub("", FENCE.sub("", text))


def links(text: str) -> list[str]:
    """Every link target of a Markdown page, in order."""
    body = prose(text)
    return [m.group(1) for pattern in (LINK, REFERENCE, AUTOLINK) for m in pattern.finditer(body)]


def slug(heading: str) -> str:
    """GitHub's anchor of a heading: markup and punctuation dropped, lower case, spaces to hyphens."""
    text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", heading)  # a link in a heading keeps its text
    text = text.replace("`", "").replace("*", "")
    kept = "".join(c for c in text.lower() if c in " -_" or unicodedata.category(c)[0] in "LN")
    return kept.replace(" ", "-")


def anchors(text: str) -> set[str]:
    """The anchors of a page's headings (a repeated heading gets ``-1``, ``-2``... as on GitHub)."""
    seen: dict[str, int] = {}
    out = set()
    for m in HEADING.finditer(FENCE.sub("", text)):
        base = slug(m.group(2))
        n = seen.get(base, 0)
        out.add(base if n == 0 else f"{base}-{n}")
        seen[base] = n + 1
    return out


def problem(page: Path, target: str, root: Path = ROOT) -> str | None:
    """Why ``target``, linked from ``page``, does not resolve in the repository at ``root`` (None: it does)."""
    parts = urlsplit(target)
    if parts.scheme in ("http", "https"):
        ok = parts.netloc and "." in parts.netloc and " " not in target
        return None if ok else "not a well-formed http(s) URL"
    if parts.scheme == "mailto":
        return None if re.fullmatch(r"[^@\s]+@[^@\s]+\.[^@\s]+", parts.path) else "not a well-formed address"
    if parts.scheme or parts.netloc:
        return f"scheme {parts.scheme!r} is neither http(s) nor a path in the repository"
    path = unquote(parts.path)
    if path.startswith("/"):
        return "an absolute path: link relative to the page"
    file = (page.parent / path).resolve() if path else page.resolve()
    if not file.is_relative_to(root.resolve()):
        return "leaves the repository (a clone has nothing beside it)"
    if not file.exists():
        return "no such file in the repository"
    if parts.fragment:
        if file.suffix != ".md":
            return "an anchor into a file that is not Markdown"
        if unquote(parts.fragment) not in anchors(file.read_text(encoding="utf-8")):
            return f"no heading with the anchor #{parts.fragment} in {file.relative_to(root.resolve())}"
    return None


def _cases():
    for page in PAGES:
        for target in links(page.read_text(encoding="utf-8")):
            yield pytest.param(page, target, id=f"{page.relative_to(ROOT)}:{target}")


def test_the_pages_have_links_to_check():
    found = {page.relative_to(ROOT).as_posix(): links(page.read_text(encoding="utf-8")) for page in PAGES}
    assert "docs/model.md" in found, "docs/model.md is missing"
    assert any("docs/model.md" in t for t in found["README.md"])
    assert len(found["README.md"]) >= 10 and len(found["docs/model.md"]) >= 5 and len(found["docs/index.md"]) >= 15
    site = [name for name in found if name.startswith("docs/") and name != "docs/index.md"]
    unlinked = [name for name in site if not any(name in t for t in found["README.md"]) and
                not any(name.removeprefix("docs/") in t for t in found["docs/index.md"])]
    assert not unlinked, f"pages neither the README nor the site's home page links to: {unlinked}"


@pytest.mark.parametrize("page, target", list(_cases()))
def test_every_link_finds_its_target_in_the_repository(page, target):
    why = problem(page, target)
    assert why is None, f"{page.relative_to(ROOT)} links to {target}: {why}"


def test_no_page_points_outside_the_repository_even_in_code():
    """A path into the folder beside the checkout (``../shared``) is not there in a clone, linked or not."""
    for page in PAGES:
        text = page.read_text(encoding="utf-8")
        assert "../shared" not in text and "MODEL.md" not in text, page.name


@pytest.mark.parametrize("target, why", [
    ("../../shared/MODEL.md", "leaves the repository"),
    ("nothing.md", "no such file"),
    ("#no-such-heading", "no heading with the anchor #no-such-heading"),
    ("guide/wind.md#nowhere", "no heading with the anchor #nowhere in docs/guide/wind.md"),
    ("figures/crazyflie-gust.png#x", "not Markdown"),
    ("/etc/passwd", "an absolute path"),
    ("https//example.com", "no such file"),
    ("http://", "not a well-formed"),
    ("ftp://example.com/x", "neither http(s) nor a path"),
    ("model.md#motors", None),
    ("#what-quadctl-corrects-in-the-report", None),
    ("guide/flying.md#flight-config-keys", None),
    ("../configs/hover.yaml", None),
    ("https://www.example.com/a(b)", None),
])
def test_a_broken_link_is_found(target, why):
    """The check is not blind: each kind of broken link is named, and good ones pass (from docs/model.md)."""
    got = problem(ROOT / "docs" / "model.md", target)
    assert (got is None) if why is None else (got is not None and why in got), got


def test_links_in_code_are_not_links_and_headings_anchor_as_on_github():
    text = "# A `code` Title: it's here\n## Wind\n## Wind\n```\n[x](../shared/y)\n```\nsee `[a](b)` and [c](#wind-1)\n"
    assert links(text) == ["#wind-1"]
    assert anchors(text) == {"a-code-title-its-here", "wind", "wind-1"}
    assert slug("From the report's design to one that flies") == "from-the-reports-design-to-one-that-flies"
    assert slug("Attitude (report eqs. 6-7)") == "attitude-report-eqs-6-7"


CONFIG_FILES = sorted(p for folder in ("configs", "docs/configs", "examples") for p in (ROOT / folder).glob("*.yaml"))
PAGE_NAMED = re.compile(r"(docs/[\w/.-]+\.md)(?:, \"([^\"]+)\")?")
README_SECTION = re.compile(r"README,? \"([^\"]+)\"")


def config_comments(text: str) -> str:
    """A YAML file's whole-line comments, joined into one line (a reference may wrap)."""
    return " ".join(line.strip()[1:].strip() for line in text.splitlines() if line.strip().startswith("#"))


@pytest.mark.parametrize("path", CONFIG_FILES, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_the_pages_and_sections_a_config_file_sends_the_reader_to_exist(path):
    """Bundled and documented configs sent the reader to the README's "From the report's design to one that
    flies", a section the README no longer has (its steps are on docs/guide/flying.md)."""
    comments = config_comments(path.read_text(encoding="utf-8"))
    readme = anchors((ROOT / "README.md").read_text(encoding="utf-8"))
    for section in README_SECTION.findall(comments):
        assert slug(section) in readme, f"{path.name}: the README has no section {section!r}"
    for page, section in PAGE_NAMED.findall(comments):
        assert (ROOT / page).is_file(), f"{path.name}: no page {page}"
        if section:
            assert slug(section) in anchors((ROOT / page).read_text(encoding="utf-8")), \
                f"{path.name}: {page} has no section {section!r}"
