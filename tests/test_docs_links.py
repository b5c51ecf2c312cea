"""The README and the pages under docs/ point at things that exist: every relative link (text or
image) names an existing file, every ``#anchor`` a heading of its page, and every repository path
written in backquotes (``serenity/...``, ``benchmarks/...``, ...) an existing file or folder."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = sorted([ROOT / "README.md", ROOT / "CHANGELOG.md", *(ROOT / "docs").glob("*.md")])
PAGES = [p for p in PAGES if p.exists()]

LINK = re.compile(r"\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")
"""The target of every markdown link or image, ``[text](target)`` or ``![alt](target)``, nested ones too."""
CODE_BLOCK = re.compile(r"^(```|~~~).*?^\1", re.M | re.S)
INLINE_CODE = re.compile(r"`([^`\n]+)`")
#: top-level folders whose paths the pages name in backquotes
REPO_DIRS = ("serenity/", "benchmarks/", "examples/", "tools/", "tests/", "docs/")


def _prose(text: str) -> str:
    """The page without its fenced code blocks (a shell line or a TOML sample is not a link)."""
    return CODE_BLOCK.sub("", text)


def slug(heading: str) -> str:
    """GitHub's anchor for a heading: lower case, punctuation dropped, spaces to hyphens."""
    text = re.sub(r"[`*_]", "", heading.strip().lower())
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def anchors(page: Path) -> set[str]:
    out: set[str] = set()
    seen: dict[str, int] = {}
    for line in _prose(page.read_text(encoding="utf-8")).splitlines():
        m = re.match(r"^#{1,6}\s+(.*?)\s*#*\s*$", line)
        if m:
            s = slug(m.group(1))
            n = seen.get(s, 0)
            seen[s] = n + 1
            out.add(s if n == 0 else f"{s}-{n}")
    return out


def links(page: Path) -> list[str]:
    return [m.group(1) for m in LINK.finditer(_prose(page.read_text(encoding="utf-8")))]


def test_the_pages_exist_and_have_links():
    """Guards the tests below against vacuity: the README and several docs pages, with links in them."""
    names = {p.name for p in PAGES}
    assert "README.md" in names and len(PAGES) >= 4
    assert sum(len(links(p)) for p in PAGES) >= 20


def test_slug_follows_github():
    assert slug("Sun shadows: cascaded shadow maps and PCSS") == "sun-shadows-cascaded-shadow-maps-and-pcss"
    assert slug("The `serenity` command") == "the-serenity-command"
    assert slug("Install and run") == "install-and-run"


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_relative_links_resolve(page):
    bad = []
    for target in links(page):
        if re.match(r"^[a-z][a-z0-9+.-]*:", target):  # http:, https:, mailto:
            continue
        path, _, anchor = target.partition("#")
        dest = (page.parent / path).resolve() if path else page
        if not dest.exists():
            bad.append(f"{target}: no such file")
        elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
            bad.append(f"{target}: no heading #{anchor} in {dest.relative_to(ROOT)}")
    assert not bad, f"{page.relative_to(ROOT)}:\n" + "\n".join(bad)


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_repository_paths_exist(page):
    bad = []
    for code in INLINE_CODE.findall(_prose(page.read_text(encoding="utf-8"))):
        for word in code.split():
            word = word.rstrip(".,;:)")
            if not word.startswith(REPO_DIRS) or any(c in word for c in "*<>{}[]|$"):
                continue
            if not (ROOT / word).exists():
                bad.append(word)
    assert not bad, f"{page.relative_to(ROOT)} names paths that do not exist: {', '.join(sorted(set(bad)))}"
