"""tools/precompile.py and the Makefile step: numba's kernels are compiled at set-up.

The first run after `make setup` used to spend ~15 s (a quiet machine) compiling the
kernels. The set-up now runs every kernel once (their cache files are written), again whenever
a file they are compiled from changes.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parent.parent
PRECOMPILE = REPO / "tools" / "precompile.py"


def _make_would_run(stamp: Path, *touched: str) -> str:
    """The commands `make setup` would run if `touched` had just changed (nothing runs).

    With the step's stamp a new file of the test's: done, newer than every source.
    """
    stamp.touch()
    proc = subprocess.run(["make", "-n", f"NUMBA_STAMP={stamp}",
                           *(f"-W{path}" for path in touched), "setup"],
                          cwd=REPO, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    return proc.stdout


def test_setup_compiles_the_kernels_when_a_file_they_are_made_of_changes(tmp_path):
    stamp, step = tmp_path / "stamp-numba", ".venv/bin/python tools/precompile.py"
    assert step in _make_would_run(stamp, "tools/precompile.py")
    assert step in _make_would_run(stamp, "amr_sim/lidar.py")  # kernels
    assert step in _make_would_run(stamp, "amr_common/robot.py")  # a constant compiled in
    assert step not in _make_would_run(stamp, "amr_sim/simulator_node.py")  # no kernel
    assert step not in _make_would_run(stamp)


def test_the_warm_up_compiles_every_kernel_and_the_stamp_covers_their_files(tmp_path):
    # From nothing, in a process of its own: numba's cache in a folder of the test's
    # (NUMBA_CACHE_DIR), so the kernels called only by other kernels are compiled here too.
    code = ("import json, runpy; tool = runpy.run_path(%r); tool['warm_up'](); "
            "kernels = tool['kernels'](); "
            "print(json.dumps({'kernels': {name: len(k.signatures) for name, k in "
            "kernels.items()}, 'sources': [str(p) for p in tool['stamp_sources']()]}))"
            % str(PRECOMPILE))
    proc = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True,
                          text=True, timeout=600,
                          env={**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba")})
    assert proc.returncode == 0, proc.stderr
    found = json.loads(proc.stdout.splitlines()[-1])
    assert len(found["kernels"]) >= 40  # every module using amr_common.jit was searched
    assert [name for name, signatures in found["kernels"].items() if not signatures] == []
    assert list((tmp_path / "numba").rglob("*.nbc"))  # written to the cache
    modules = {name.rsplit(".", 1)[0] for name in found["kernels"]}
    sources = {Path(path) for path in found["sources"]}
    assert {REPO.joinpath(*module.split(".")).with_suffix(".py") for module in modules} \
        <= sources
