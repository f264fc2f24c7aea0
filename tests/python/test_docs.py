"""The docs are maps: every relative link in the project's Markdown resolves to a file of the
checkout, and every `#anchor` to a heading of the file it names (GitHub's heading slugs)."""

import pathlib
import re

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
DOCS = sorted({ROOT / "README.md", ROOT / "ARCHITECTURE.md", *ROOT.glob("docs/*.md"), ROOT / "src/scene/FORMAT.md",
               *ROOT.glob("references/**/*.md"), *ROOT.glob("src/**/*.md")})
LINK = re.compile(r"(?<!!)\[[^\]]*\]\(([^)\s]+)\)")
FENCE = re.compile(r"^```.*?^```", re.S | re.M)


def slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces to hyphens."""
    s = re.sub(r"[`*_]", "", heading.strip().lower())
    s = re.sub(r"[^\w\- ]", "", s)
    return s.replace(" ", "-")


def anchors(md: pathlib.Path) -> set[str]:
    text = FENCE.sub("", md.read_text())
    return {slug(m.group(1)) for m in re.finditer(r"^#{1,6}\s+(.*)$", text, re.M)}


def links(md: pathlib.Path) -> list[str]:
    return [m.group(1) for m in LINK.finditer(FENCE.sub("", md.read_text()))]


def broken(md: pathlib.Path) -> list[str]:
    bad = []
    for target in links(md):
        if re.match(r"[a-z]+:", target):  # http(s), mailto: not followed (no network here)
            continue
        path, _, frag = target.partition("#")
        dest = (md.parent / path).resolve() if path else md
        if not dest.exists():
            bad.append(f"{target}: no such file")
        elif frag and dest.suffix == ".md" and frag not in anchors(dest):
            bad.append(f"{target}: no heading #{frag} in {dest.relative_to(ROOT)}")
    return bad


@pytest.mark.parametrize("md", DOCS, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_relative_link_resolves(md):
    assert md.is_file()
    assert not broken(md), f"{md.relative_to(ROOT)}: " + "; ".join(broken(md))


def test_the_readme_is_a_map():
    # the two commands, the tour's pointers and no dated measurements (those live in docs/)
    text = (ROOT / "README.md").read_text()
    assert "bash harness/nightly.sh" in text and "bash harness/test.sh" in text
    assert len(text.splitlines()) <= 150
    assert not re.search(r"\b20\d\d-\d\d-\d\d\b", text), "a dated figure in the README"


def test_a_broken_link_and_a_missing_anchor_are_found(tmp_path):
    # negative control: the checker must fail on a wrong path and on a wrong anchor
    (tmp_path / "b.md").write_text("# Real heading\n")
    a = tmp_path / "a.md"
    a.write_text("[x](missing.md) [y](b.md#real-heading) [z](b.md#no-such) `[w](in-code.md)`\n"
                 "```\n[v](fenced.md)\n```\n")
    global ROOT
    saved, ROOT = ROOT, tmp_path
    try:
        assert broken(a) == ["missing.md: no such file", "b.md#no-such: no heading #no-such in b.md",
                             "in-code.md: no such file"]
    finally:
        ROOT = saved
