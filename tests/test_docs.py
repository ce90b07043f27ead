"""Every relative link and image in README.md and docs/*.md resolves, anchors included.

Anchors follow GitHub's heading slugs (github-slugger): the heading's rendered text in lower
case, punctuation other than '-' and '_' removed, each space a '-', and a repeated slug
numbered '-1', '-2', ... Links inside code (fenced blocks, `spans`) are not links.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

# Pages linked from the README and docs/index.md before they are written (none now). Once
# a page exists it is checked like any other, anchors included.
NOT_YET_WRITTEN: set[Path] = set()  # pages linked before they are written

FENCE = re.compile(r"^ {0,3}(`{3,}|~{3,})")
HEADING = re.compile(r"^ {0,3}(#{1,6})[ \t]+(.*?)(?:[ \t]+#+)?[ \t]*$")
# [text](target) and ![alt](target); the text may span lines, the target may not.
INLINE_LINK = re.compile(r"!?\[((?:[^\[\]]|\[[^\[\]]*\])*)\]"  # [text], one level of [] inside
                         r"\(\s*<?([^)\s>]*)>?(?:\s+\"[^\"]*\")?\s*\)")  # (target "title")
REF_DEFINITION = re.compile(r"^ {0,3}\[[^\]]+\]:\s*<?(\S+?)>?(?:\s+.*)?$", re.MULTILINE)
CODE_SPAN = re.compile(r"(`+)(.+?)\1", re.DOTALL)
SCHEME = re.compile(r"^[A-Za-z][A-Za-z0-9+.-]*:")


def doc_files() -> list[Path]:
    return [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


def prose(text: str) -> str:
    """The text with fenced code blocks blanked (line numbers kept)."""
    lines, fence = [], None
    for line in text.splitlines():
        m = FENCE.match(line)
        if fence is None and m:
            fence = m.group(1)[0] * len(m.group(1))
            lines.append("")
        elif fence is not None:
            if line.strip().startswith(fence) and set(line.strip()) == {fence[0]}:
                fence = None
            lines.append("")
        elif line.startswith("    ") and (not lines or not lines[-1].strip()
                                        or lines[-1].startswith("    ")):
            lines.append("    ")  # an indented code block
        else:
            lines.append(line)
    return "\n".join(lines)


def rendered(heading: str) -> str:
    """A heading's text as GitHub renders it: links as their text, no code or emphasis marks."""
    text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", heading)
    text = CODE_SPAN.sub(lambda m: m.group(2), text)
    text = re.sub(r"<[^>]+>", "", text)
    return re.sub(r"(\*\*|__|\*)", "", text)


def slug(text: str) -> str:
    return re.sub(r"[^\w\- ]", "", text.lower()).replace(" ", "-")


def anchors(text: str) -> set[str]:
    seen: dict[str, int] = {}
    out = set()
    for line in prose(text).splitlines():
        m = HEADING.match(line)
        if not m:
            continue
        base = slug(rendered(m.group(2)))
        n = seen.get(base, 0)
        seen[base] = n + 1
        out.add(base if n == 0 else f"{base}-{n}")
    return out


def links(text: str) -> list[tuple[int, str]]:
    """(line, target) of every link and image outside code."""
    body = prose(text)
    body = CODE_SPAN.sub(lambda m: re.sub(r"[^\n]", " ", m.group(0)), body)
    found = [(body.count("\n", 0, m.start()) + 1, m.group(2))
             for m in INLINE_LINK.finditer(body)]
    found += [(body.count("\n", 0, m.start()) + 1, m.group(1))
              for m in REF_DEFINITION.finditer(body)]
    return found


def broken(path: Path, root: Path = ROOT) -> list[str]:
    """'file:line: target: why' for every local link of the file that does not resolve."""
    problems = []
    for line, target in links(path.read_text(encoding="utf-8")):
        if not target or SCHEME.match(target) or target.startswith("//"):
            continue
        file_part, _, anchor = target.partition("#")
        dest = (path.parent / file_part).resolve() if file_part else path
        where = f"{path.relative_to(root)}:{line}: {target}"
        if not dest.exists():
            if dest not in NOT_YET_WRITTEN:
                problems.append(f"{where}: no such file")
            continue
        if (anchor and dest.suffix == ".md"
                and anchor not in anchors(dest.read_text(encoding="utf-8"))):
            problems.append(f"{where}: no heading with the anchor '#{anchor}'")
    return problems


@pytest.mark.parametrize("path", doc_files(), ids=lambda p: str(p.relative_to(ROOT)))
def test_every_local_link_and_image_resolves(path):
    assert broken(path) == []


def test_the_docs_pages_are_all_linked_from_the_readme():
    readme_targets = {(ROOT / t.partition("#")[0]).resolve()
                      for _, t in links((ROOT / "README.md").read_text(encoding="utf-8"))
                      if t and not SCHEME.match(t)}
    pages = set(doc_files()[1:]) | NOT_YET_WRITTEN
    assert sorted(str(p.relative_to(ROOT)) for p in pages - readme_targets) == []


def test_the_quick_start_has_two_commands_and_ci_runs_the_second():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    section = text.split("\n## Quick start\n", 1)[1].split("\n## ", 1)[0]
    commands = re.findall(r"```sh\n(.*?)\n```", section, re.DOTALL)
    assert commands == [
        "bash scripts/install.sh pocl && .venv/bin/gpucompgen run models/vision_system.yaml"
        " --frames 60 --frames-in-flight 3",
        "bash scripts/install.sh pocl,test && .venv/bin/python -m pytest -n 2",
    ]
    assert commands[1] in (ROOT / ".ci" / "run").read_text(encoding="utf-8")


# The checker itself, against hand-made pages and GitHub's own slugs.

@pytest.mark.parametrize(("heading", "expected"), [
    ("## Quick start", "quick-start"),
    ("## `gpucompgen types`", "gpucompgen-types"),
    ("### Model checks: `gpucompgen check`", "model-checks-gpucompgen-check"),
    ("## What's new?", "whats-new"),
    ("## C++ & Python", "c--python"),
    ("## The **bold** [link](x.md) heading ##", "the-bold-link-heading"),
    ("# snake_case_name", "snake_case_name"),
])
def test_slugs_are_githubs(heading, expected):
    assert anchors(heading + "\n") == {expected}


def test_repeated_headings_are_numbered():
    assert anchors("# Usage\n## Usage\n### Usage\n") == {"usage", "usage-1", "usage-2"}


def test_the_checker_finds_what_is_broken_and_ignores_code(tmp_path):
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "other.md").write_text("# Other page\n## A section\n")
    (tmp_path / "docs" / "pic.png").write_bytes(b"")
    page = tmp_path / "docs" / "page.md"
    page.write_text(
        "# Page\n"
        "[ok](other.md) [ok](other.md#a-section) [ok](#page) ![ok](pic.png)\n"
        "[gone](missing.md) ![gone](missing.png)\n"
        "[bad anchor](other.md#no-such) [bad](#nowhere)\n"
        "[split\nacross lines](also-missing.md)\n"
        "`[not a link](in-code.md)` [web](https://example.com/x.md)\n"
        "```\n[not a link](in-fence.md)\n```\n"
        "[ref]: ref-missing.md\n"
        "## Closing hashes ##\n[ok](#closing-hashes) [ok](#c)\n# C#\n")
    assert broken(page, tmp_path) == [
        "docs/page.md:3: missing.md: no such file",
        "docs/page.md:3: missing.png: no such file",
        "docs/page.md:4: other.md#no-such: no heading with the anchor '#no-such'",
        "docs/page.md:4: #nowhere: no heading with the anchor '#nowhere'",
        "docs/page.md:5: also-missing.md: no such file",
        "docs/page.md:11: ref-missing.md: no such file",
    ]
