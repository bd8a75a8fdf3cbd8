"""`.ci/run`: the README's test command as a newcomer runs it, with a fresh empty HOME.

The suite once passed where an earlier run had left `~/.ray/auth_token` and failed on a
new machine; CI now runs `make test` with HOME a new empty folder it removes afterwards.
(Here with a stand-in `make` on PATH that notes what it was given: the suite itself is the
command, it cannot run inside itself.)
"""
from __future__ import annotations

import os
import stat
import subprocess
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def test_ci_runs_make_test_with_a_fresh_empty_home_and_removes_it(tmp_path):
    seen = tmp_path / "seen"
    stub = tmp_path / "bin" / "make"
    stub.parent.mkdir()
    stub.write_text('#!/bin/sh\n{ echo "$HOME"; ls -A "$HOME" | wc -l; echo "$*"; '
                    'echo "${RAY_AUTH_TOKEN:-none} ${XDG_CACHE_HOME:-none}"; } > "$SEEN"\n'
                    'exit 3\n')
    stub.chmod(stub.stat().st_mode | stat.S_IXUSR)
    env = {**os.environ, "PATH": f"{stub.parent}:{os.environ['PATH']}", "SEEN": str(seen),
           "PYTEST_ARGS": "-k sim", "RAY_AUTH_TOKEN": "the-users",
           "XDG_CACHE_HOME": str(Path.home() / ".cache")}
    proc = subprocess.run([str(REPO / ".ci" / "run")], env=env, capture_output=True,
                          text=True, timeout=60)
    assert proc.returncode == 3, proc.stderr  # make's exit code is CI's
    home, entries, args, leaked = seen.read_text().splitlines()
    assert Path(home) != Path.home() and entries == "0"
    assert args == "test PYTEST_ARGS=-k sim"
    assert leaked == "none none"  # nothing of the caller's home comes along
    assert not Path(home).exists()  # removed at the end
