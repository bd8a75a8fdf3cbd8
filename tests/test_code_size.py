"""tools/long_code.py, the review prompt on size, finds long code and accepts a reason."""
from __future__ import annotations

from tools.long_code import FUNCTION_LINES, MODULE_LINES, long_code_without_a_reason


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
