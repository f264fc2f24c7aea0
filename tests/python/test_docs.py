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


# The Python API reference, generated from the package's docstrings and _core.pyi (pdoc):
# `.venv/bin/python -m pdoc progmo -o out/api` (README.md, "Where to read more").
def html_links(page: pathlib.Path) -> list[str]:
    return re.findall(r'href="([^"]+)"', page.read_text())


def html_broken(folder: pathlib.Path) -> list[str]:
    """Relative links of the generated pages that name no file, or no id of the page they name."""
    bad = []
    for page in folder.rglob("*.html"):
        for target in html_links(page):
            if re.match(r"[a-z]+:", target):
                continue
            path, _, frag = target.partition("#")
            dest = (page.parent / path).resolve() if path else page
            if not dest.exists():
                bad.append(f"{page.name}: {target}: no such file")
            elif frag and f'id="{frag}"' not in dest.read_text():
                bad.append(f"{page.name}: {target}: no id {frag}")
    return bad


def test_the_api_reference_builds_with_every_public_name_and_no_broken_link(tmp_path):
    import subprocess
    import sys

    import progmo

    out = tmp_path / "api"
    r = subprocess.run([sys.executable, "-m", "pdoc", "progmo", "-o", str(out)],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    page = (out / "progmo.html").read_text()
    missing = [n for n in progmo.__all__ if f'id="{n}"' not in page]
    assert not missing, f"public names without an entry: {missing}"
    # the settings reach the reference through Scene.solve's docstring
    assert 'id="Scene.solve"' in page and "SETTINGS" in page
    assert not html_broken(out), html_broken(out)
    # negative control: a link to an id no page has is found
    (out / "extra.html").write_text('<a href="progmo.html#NoSuchName">x</a>')
    assert html_broken(out) == ["extra.html: progmo.html#NoSuchName: no id NoSuchName"]
