"""The README stays a short front door and the user text speaks for itself.

The manual itself is checked by `mkdocs build --strict` in `make test` (every page, picture and
anchor it links); these checks cover what MkDocs does not build: the README (read on the
forge and in the checkout), the changelog, and the comments and messages in the code, which
must not point at issue-tracker numbers a user cannot see.
"""
from __future__ import annotations

import io
import os
import re
import tokenize
from pathlib import Path

import pytest

# The checkout's root, wherever in tests/ this file sits.
REPO = next(folder for folder in Path(__file__).resolve().parents
            if (folder / "pyproject.toml").is_file())
README = REPO / "README.md"
MAX_README_LINES = 400
# Folders that hold no text of this project: environments, build output, other projects' code.
_NOT_OURS = {".git", ".venv", "build", "site", "dist", "node_modules", "__pycache__",
             "third_party", ".pytest_cache", "out", "maps"}
# The word issue with a number after it (with or without a hash), and a hash with a number
# after it on its own; a Markdown heading's hash and a space, and a colour in a string, are
# neither (see the cases of test_the_tracker_number_check).
_ISSUE = re.compile(r"\bissues?\s*#?\d+", re.IGNORECASE)
_HASH_NUMBER = re.compile(r"(?<![\w&/#])#\d+\b")


def _our_files(*suffixes: str) -> list[Path]:
    found = []
    for folder, subfolders, files in os.walk(REPO):
        subfolders[:] = [name for name in subfolders if name not in _NOT_OURS]
        found += [Path(folder) / name for name in files
                  if Path(name).suffix in suffixes or name in suffixes]
    return sorted(found)


def _prose(markdown: str) -> str:
    """Markdown without fenced code blocks and inline code (commands may hold anything)."""
    without_fences = re.sub(r"^```.*?^```", "", markdown, flags=re.MULTILINE | re.DOTALL)
    return re.sub(r"`[^`\n]*`", "", without_fences)


def _python_comments_and_strings(source: str) -> tuple[str, str]:
    comments, strings = [], []
    for token in tokenize.generate_tokens(io.StringIO(source).readline):
        if token.type == tokenize.COMMENT:
            comments.append(token.string)
        elif token.type == tokenize.STRING:
            strings.append(token.string)
    return "\n".join(comments), "\n".join(strings)


def _tracker_numbers(text: str, *, hash_numbers: bool) -> list[str]:
    found = _ISSUE.findall(text)
    if hash_numbers:
        found += _HASH_NUMBER.findall(text)
    return found


def _github_slug(heading: str, seen: dict[str, int]) -> str:
    """The anchor GitHub gives a heading: lower case, punctuation dropped, spaces to hyphens."""
    slug = re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")
    count = seen.get(slug, 0)
    seen[slug] = count + 1
    return slug if count == 0 else f"{slug}-{count}"


def _anchors(markdown_file: Path) -> set[str]:
    seen: dict[str, int] = {}
    anchors, in_fence = set(), False
    for line in markdown_file.read_text(encoding="utf-8").splitlines():
        if line.startswith("```"):
            in_fence = not in_fence
        elif not in_fence and (heading := re.match(r"#{1,6} (.+)", line)):
            anchors.add(_github_slug(heading.group(1), seen))
    return anchors


def _setup_section(readme: str) -> str:
    match = re.search(r"^## Set up and run\n(.*?)(?=^## )", readme, re.MULTILINE | re.DOTALL)
    assert match, "the README has no '## Set up and run' section"
    return match.group(1)


def test_the_readme_is_at_most_400_lines():
    lines = README.read_text(encoding="utf-8").splitlines()
    assert len(lines) <= MAX_README_LINES, (
        f"README.md has {len(lines)} lines (at most {MAX_README_LINES}): move the manual's text "
        "to a page in docs/ and link it")


def test_the_readme_sets_up_a_fresh_machine_with_exactly_two_commands():
    section = _setup_section(README.read_text(encoding="utf-8"))
    commands = [line.split("#")[0].strip() for line in section.splitlines()
                if line.startswith("    ") and line.strip()]
    assert commands == ["make run", "make test"]
    makefile = (REPO / "Makefile").read_text(encoding="utf-8")
    assert re.search(r"^run:", makefile, re.MULTILINE)
    assert re.search(r"^test:", makefile, re.MULTILINE)


def test_the_setup_check_finds_a_third_command():
    readme = "## Set up and run\n\n    make run\n    make test\n    make bench\n\n## Next\n"
    section = _setup_section(readme)
    commands = [line.split("#")[0].strip() for line in section.splitlines()
                if line.startswith("    ") and line.strip()]
    assert commands != ["make run", "make test"]


def test_every_relative_link_of_the_readme_resolves():
    readme = README.read_text(encoding="utf-8")
    targets = re.findall(r"\]\(([^)\s]+)\)", _without_code(readme))
    assert targets, "no links found: the pattern is wrong"
    broken = []
    for target in targets:
        if re.match(r"[a-z][a-z0-9+.-]*:", target):  # http:, https:, mailto:
            continue
        path_part, _, anchor = target.partition("#")
        path = (README.parent / path_part) if path_part else README
        if not path.exists():
            broken.append(f"{target}: no such file")
        elif anchor and path.suffix == ".md" and anchor not in _anchors(path):
            broken.append(f"{target}: {path.name} has no heading with that anchor")
    assert not broken, "README links that do not resolve:\n" + "\n".join(broken)


def _without_code(markdown: str) -> str:
    return re.sub(r"^```.*?^```", "", markdown, flags=re.MULTILINE | re.DOTALL)


def test_the_link_check_finds_a_missing_anchor(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("# Title\n\n## Map (SLAM)\n\n```python\n# not a heading\n```\n")
    assert _anchors(page) == {"title", "map-slam"}


# The samples are put together at run time, so that this file passes its own check.
_N, _HASH = "21", "#"


@pytest.mark.parametrize("text, found", [
    (f"called turtlebot3 until issue {_N}", [f"issue {_N}"]),
    (f"Issues {_N} and 22 measured it", [f"Issues {_N}"]),
    (f"(issue {_N} {_HASH}9 follow-up)", [f"issue {_N}", f"{_HASH}9"]),
    ("a new issue of the course", []),
    (f"## Heading and a PKCS{_HASH}8 key", []),
])
def test_the_tracker_number_check(text, found):
    assert _tracker_numbers(text, hash_numbers=True) == found


def test_no_issue_numbers_in_the_user_text():
    offending = []
    for path in [README, REPO / "CHANGELOG.md", *_our_files(".md")]:
        text = _prose(path.read_text(encoding="utf-8"))
        for number in _tracker_numbers(text, hash_numbers=True):
            offending.append(f"{path.relative_to(REPO)}: {number}")
    assert not offending, ("user text cites issue numbers a reader cannot see; say what they "
                           "meant instead:\n" + "\n".join(sorted(set(offending))))


def test_no_issue_numbers_in_code_comments_or_messages():
    offending = []
    for path in _our_files(".py"):
        comments, strings = _python_comments_and_strings(path.read_text(encoding="utf-8"))
        numbers = (_tracker_numbers(comments, hash_numbers=True)
                   + _tracker_numbers(strings, hash_numbers=False))
        offending += [f"{path.relative_to(REPO)}: {number}" for number in numbers]
    for path in _our_files("Makefile", "run", ".toml", ".in", ".yaml", ".yml", ".xml", ".cfg"):
        numbers = _tracker_numbers(path.read_text(encoding="utf-8"), hash_numbers=False)
        offending += [f"{path.relative_to(REPO)}: {number}" for number in numbers]
    assert not offending, ("code cites issue numbers a reader cannot see; say what they meant "
                           "instead:\n" + "\n".join(sorted(set(offending))))
