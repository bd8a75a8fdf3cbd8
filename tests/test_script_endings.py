"""scripts/script_endings.py: a closed stdout or stderr neither raises nor costs the results.

Each case runs in its own interpreter (the guard points the real file descriptors at devnull).
"""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

SCRIPTS = Path(__file__).resolve().parent.parent / "scripts"

# Prints into a pipe nobody reads any more, then writes its result: as run_sim.py does after
# `| head` has exited.
PROGRAM = """
import sys
sys.path.insert(0, {scripts!r})
from script_endings import run_script, stdout_closed

def main():
    sys.stdin.read()  # until the test has closed the reading end
    print("a line nobody reads")
    print("an error line nobody reads", file=sys.stderr, flush=True)
    with open({result!r}, "w") as stream:
        stream.write(f"written, stdout closed: {{stdout_closed()}}")
    return 7

sys.exit(run_script(main))
"""


def _run_into_closed_pipes(tmp_path: Path, unbuffered: bool) -> tuple[int, str]:
    result = tmp_path / "result.txt"
    process = subprocess.Popen(
        [sys.executable, "-c", PROGRAM.format(scripts=str(SCRIPTS), result=str(result))],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        env=dict(os.environ, PYTHONUNBUFFERED="1" if unbuffered else ""))
    process.stdout.close()
    process.stderr.close()
    process.stdin.close()
    code = process.wait(timeout=30)
    return code, result.read_text() if result.exists() else ""


def test_prints_into_a_closed_pipe_neither_raise_nor_change_the_exit_code(tmp_path):
    # Unbuffered (python -u) the print raised; buffered, the flush at exit did (exit code 120).
    for unbuffered in (True, False):
        code, result = _run_into_closed_pipes(tmp_path, unbuffered)
        assert code == 7, unbuffered
        assert result == f"written, stdout closed: {unbuffered}", unbuffered
