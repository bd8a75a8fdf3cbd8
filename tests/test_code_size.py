"""The house rule on size: no module over 400 lines, no function over 60, without a reason.

A reason is written where the reader meets the length: a line starting `Long:` (a comment,
`# Long: ...`, or a docstring line) in a long module's first 40 lines, or in a long function's
first lines (a line above its `def` to two lines past its docstring), saying why it stays whole
(a plain-Python twin that mirrors its numba kernel line by line, a table of command-line
options, ...). The project's code, scripts and tools are checked; tests are not.
"""
from __future__ import annotations

import ast
import subprocess
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


def test_no_long_module_or_function_without_a_written_reason():
    assert long_code_without_a_reason(_sources()) == []


def test_the_check_finds_a_long_function_and_accepts_its_reason(tmp_path):
    body = "".join(f"    x{k} = {k}\n" for k in range(FUNCTION_LINES))
    bare, reasoned = tmp_path / "bare.py", tmp_path / "reasoned.py"
    bare.write_text(f'def f():\n    """Doc."""\n{body}')
    reason = "    # Long: a table, read top to bottom\n"
    reasoned.write_text(f'def f():\n    """Doc."""\n{reason}{body}')
    assert long_code_without_a_reason([bare]) == [f"{bare}:f: {FUNCTION_LINES + 2} lines"]
    assert long_code_without_a_reason([reasoned]) == []
    big, reasoned_big = tmp_path / "big.py", tmp_path / "reasoned_big.py"
    big.write_text("x = 1\n" * (MODULE_LINES + 1))
    reasoned_big.write_text('"""Doc.\n\nLong: one table."""\n' + "x = 1\n" * MODULE_LINES)
    assert long_code_without_a_reason([big]) == [f"{big}: {MODULE_LINES + 1} lines"]
    assert long_code_without_a_reason([reasoned_big]) == []
