"""A review prompt on size: the modules over 400 lines and functions over 60 without a reason.

Usage: .venv/bin/python tools/long_code.py   (lists them; always exits 0)

Size is a prompt for a reviewer, not a rule: split where a concept ends, not at a line count.

A reason is written where the reader meets the length: a line starting `Long:` (a comment,
`# Long: ...`, or a docstring line) in a long module's first 40 lines, or in a long function's
first lines (a line above its `def` to two lines past its docstring), saying why it stays whole
(a plain-Python twin that mirrors its numba kernel line by line, a table of command-line
options, ...). The project's code, scripts and tools are checked; tests are not.
"""
from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
MODULE_LINES, FUNCTION_LINES = 400, 60


def _sources() -> list[Path]:
    files = subprocess.run(["git", "ls-files", "*.py"], cwd=REPO, capture_output=True,
                           text=True, check=True).stdout.split()
    return [REPO / f for f in files if not f.startswith(("tests/", "third_party/"))]


def _is_reason(line: str) -> bool:
    return line.strip().lstrip("#").lstrip().startswith("Long:")


def _function_reason(lines: list[str], node: ast.FunctionDef | ast.AsyncFunctionDef) -> bool:
    body = node.body
    has_docstring = bool(body) and isinstance(body[0], ast.Expr) and \
        isinstance(body[0].value, ast.Constant) and isinstance(body[0].value.value, str)
    docstring_end = body[0].end_lineno if has_docstring else node.lineno
    above = min([node.lineno] + [d.lineno for d in node.decorator_list]) - 2
    return any(_is_reason(line) for line in lines[max(above, 0):docstring_end + 2])


def long_code_without_a_reason(paths: list[Path]) -> list[str]:
    """'path: N lines' / 'path:function: N lines' for each long piece with no written reason."""
    found = []
    for path in paths:
        text = path.read_text(encoding="utf-8")
        lines = text.splitlines()
        name = path.relative_to(REPO) if path.is_relative_to(REPO) else path
        if len(lines) > MODULE_LINES and not any(_is_reason(line) for line in lines[:40]):
            found.append(f"{name}: {len(lines)} lines")
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                length = node.end_lineno - node.lineno + 1
                if length > FUNCTION_LINES and not _function_reason(lines, node):
                    found.append(f"{name}:{node.name}: {length} lines")
    return found



if __name__ == "__main__":
    found = long_code_without_a_reason(_sources())
    print("\n".join(found) if found else "no long module or function without a reason")
    sys.exit(0)
