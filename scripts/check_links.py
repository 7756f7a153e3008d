#!/usr/bin/env python3
"""Check the relative links of the project's Markdown documents.

Checks README.md, every docs/**/*.md, shaders/README.md and any other
Markdown file at the top level of tests/ or docs/ (tracked by git, or
present), run from anywhere inside the repository:

    python3 scripts/check_links.py

For every inline link or image, `[text](target)` and `![alt](target)`, and
every reference definition, `[label]: target`, outside fenced code blocks
and inline code, whose target is relative (not http:, https:, mailto: or
any other scheme):

- the file or folder must exist, relative to the Markdown file (a target
  starting with `/` is taken from the repository root, as GitHub does);
- a `#anchor` must name a heading of the target Markdown file (of the same
  file for a bare `#anchor`), by GitHub's rules: the heading's text in
  lowercase, every character but letters, digits, spaces, `-` and `_`
  dropped, spaces turned to `-`, and repeated headings numbered `-1`,
  `-2`, ... in order. An explicit `<a name="...">` or `id="..."` counts too.
  Anchors into files other than Markdown are not checked.

Also fails when README.md is longer than 350 lines (the README is a
newcomer's page; the rest belongs in docs/).

Prints each problem as `file:line: broken link target (reason)` and exits
with 1; otherwise prints a one-line summary and exits with 0. Standard
library only.
"""

import os
import re
import subprocess
import sys
import unicodedata
from pathlib import Path
from urllib.parse import unquote

README_MAX_LINES = 350

FENCE = re.compile(r"^\s*(`{3,}|~{3,})")
# Inline code spans (never across a blank line).
CODE_SPAN = re.compile(r"(`+)((?:(?!\n[ \t]*\n).)*?)(?<!`)\1(?!`)", re.S)
# Link text with up to one level of nested brackets (an image inside a link).
LINK = re.compile(
    r"(!?)\[((?:[^\[\]]|\[[^\[\]]*\])*)\]"  # [text] or ![alt]
    r"\(\s*(<[^>\n]*>|[^\s()]*(?:\([^\s()]*\)[^\s()]*)*)"  # (target
    r"(?:\s+(?:\"[^\"]*\"|'[^']*'|\([^)]*\)))?\s*\)"  # optional "title")
)
REF_DEF = re.compile(r"^ {0,3}\[([^\]]+)\]:\s*(<[^>\n]*>|\S+)", re.M)
SCHEME = re.compile(r"^[A-Za-z][A-Za-z0-9+.-]*:")
ATX = re.compile(r"^ {0,3}(#{1,6})(?:[ \t]+(.*?))?(?:[ \t]+#+)?[ \t]*$")
SETEXT = re.compile(r"^ {0,3}(=+|-+)[ \t]*$")
HTML_ANCHOR = re.compile(r"<a\s[^>]*?\b(?:name|id)\s*=\s*[\"']([^\"']+)[\"']", re.I)
HTML_ID = re.compile(r"<[a-z][^>]*?\bid\s*=\s*[\"']([^\"']+)[\"']", re.I)


def repo_root() -> Path:
    here = Path(__file__).resolve().parent
    try:
        out = subprocess.run(
            ["git", "rev-parse", "--show-toplevel"], cwd=here, capture_output=True, text=True, check=True
        ).stdout.strip()
        if out:
            return Path(out)
    except (OSError, subprocess.CalledProcessError):
        pass
    return here.parent


def tracked_top_level_md(root: Path, folder: str) -> set:
    """Tracked *.md files directly in `folder` (empty when git is not there)."""
    try:
        out = subprocess.run(
            ["git", "ls-files", "--", f"{folder}/*.md"], cwd=root, capture_output=True, text=True, check=True
        ).stdout
    except (OSError, subprocess.CalledProcessError):
        return set()
    return {root / p for p in out.splitlines() if p.count("/") == 1}


def documents(root: Path) -> list:
    files = {root / "README.md", root / "shaders" / "README.md"}
    files |= set((root / "docs").rglob("*.md"))
    files |= set((root / "tests").glob("*.md"))
    for folder in ("docs", "tests"):
        files |= tracked_top_level_md(root, folder)
    return sorted(f for f in files if f.is_file())


def blank_fences(text: str) -> str:
    """The text with fenced code blocks blanked, line numbers kept."""
    out, fence = [], None
    for line in text.split("\n"):
        m = FENCE.match(line)
        if fence is None:
            if m:
                fence = m.group(1)
                out.append("")
                continue
            out.append(line)
        else:
            if m and m.group(1)[0] == fence[0] and len(m.group(1)) >= len(fence) and not line.strip()[len(m.group(1)):].strip():
                fence = None
            out.append("")
    return "\n".join(out)


def blank_code_spans(text: str) -> str:
    """Inline code replaced by spaces of the same length (offsets kept)."""
    return CODE_SPAN.sub(lambda m: re.sub(r"[^\n]", " ", m.group(0)), text)


def heading_text(raw: str) -> str:
    """What GitHub renders of a heading's Markdown, near enough for slugs."""
    parts, pos = [], 0
    for m in CODE_SPAN.finditer(raw):
        parts.append(("md", raw[pos : m.start()]))
        parts.append(("code", m.group(2).strip() if m.group(2).strip() else m.group(2)))
        pos = m.end()
    parts.append(("md", raw[pos:]))
    out = []
    for kind, s in parts:
        if kind == "md":
            s = re.sub(r"!?\[((?:[^\[\]]|\[[^\[\]]*\])*)\]\([^)]*\)", r"\1", s)  # links, images: their text
            s = re.sub(r"<[^>]+>", "", s)  # inline HTML
            s = re.sub(r"(?<![\w])_+|_+(?![\w])", "", s)  # emphasis underscores, not snake_case
        out.append(s)
    return "".join(out)


def slug(raw: str) -> str:
    text = heading_text(raw).strip().lower()
    kept = []
    for ch in text:
        cat = unicodedata.category(ch)
        if ch in "-_ " or cat[0] in "LN" or cat == "Mn":
            kept.append(ch)
    return "".join(kept).replace(" ", "-")


_anchor_cache: dict = {}


def anchors(path: Path) -> set:
    """Every anchor GitHub makes for the headings of a Markdown file."""
    if path in _anchor_cache:
        return _anchor_cache[path]
    text = blank_fences(path.read_text(encoding="utf-8"))
    lines = text.split("\n")
    seen: dict = {}
    found = set()

    def add(base: str) -> None:
        n = seen.get(base, 0)
        found.add(base if n == 0 else f"{base}-{n}")
        seen[base] = n + 1

    for i, line in enumerate(lines):
        m = ATX.match(line)
        if m:
            add(slug(m.group(2) or ""))
            continue
        if i > 0 and SETEXT.match(line) and lines[i - 1].strip() and not ATX.match(lines[i - 1]):
            prev = lines[i - 1]
            # A '---' under a table row or list item is not a heading underline.
            if not (line.strip().startswith("-") and (prev.lstrip().startswith(("|", "- ", "* ")) or "|" in prev)):
                add(slug(prev))
    for m in HTML_ANCHOR.finditer(text):
        found.add(m.group(1))
    for m in HTML_ID.finditer(text):
        found.add(m.group(1))
    _anchor_cache[path] = found
    return found


def check_target(root: Path, doc: Path, target: str):
    """None when the target is fine (or not ours to check), else the reason."""
    if target.startswith("<") and target.endswith(">"):
        target = target[1:-1]
    if not target or SCHEME.match(target):
        return None
    path_part, _, anchor = target.partition("#")
    path_part = unquote(path_part.split("?", 1)[0])
    if path_part:
        dest = (root / path_part.lstrip("/")) if path_part.startswith("/") else (doc.parent / path_part)
        if not dest.exists():
            return "no such file"
    else:
        dest = doc
    if anchor:
        if dest.is_dir() or dest.suffix.lower() not in (".md", ".markdown"):
            return None
        if unquote(anchor) not in anchors(dest.resolve()):
            return f"no heading for #{anchor} in {os.path.relpath(dest, root)}"
    return None


def main() -> int:
    root = repo_root()
    problems, links, anchored, docs = [], 0, 0, documents(root)
    for doc in docs:
        rel = os.path.relpath(doc, root)
        text = blank_code_spans(blank_fences(doc.read_text(encoding="utf-8")))
        found = [(m.start(), m.group(3)) for m in LINK.finditer(text)]
        found += [(m.start(2), m.group(2)) for m in REF_DEF.finditer(text)]
        for start, target in sorted(found):
            line = text.count("\n", 0, start) + 1
            t = target[1:-1] if target.startswith("<") and target.endswith(">") else target
            if not t or SCHEME.match(t):
                continue
            links += 1
            anchored += "#" in t
            reason = check_target(root, doc, target)
            if reason:
                problems.append(f"{rel}:{line}: broken link {t} ({reason})")
    readme = root / "README.md"
    readme_lines = len(readme.read_text(encoding="utf-8").splitlines()) if readme.is_file() else 0
    if readme_lines > README_MAX_LINES:
        problems.append(f"README.md:{README_MAX_LINES + 1}: README.md has {readme_lines} lines (more than {README_MAX_LINES}; move the rest to docs/)")
    for p in problems:
        print(p)
    if problems:
        print(f"{len(problems)} problem(s)", file=sys.stderr)
        return 1
    print(f"ok: {links} relative links ({anchored} with anchors) in {len(docs)} files, all resolve; README.md has {readme_lines} lines (limit {README_MAX_LINES})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
