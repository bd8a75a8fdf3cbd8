"""Run tests/robot_emulator.py as a separate process and read its JSON-lines log.

The emulator speaks Cyclone DDS in the calling test's ROS domain (the `ros` fixture's); tests
that drive it import these helpers.
"""
from __future__ import annotations

import contextlib
import json
import os
import subprocess
import sys
from pathlib import Path

from tests.processes import terminate

EMULATOR = Path(__file__).with_name("robot_emulator.py")


@contextlib.contextmanager
def running_emulator(tmp_path: Path, *options: str):
    """Start the emulator in this test's ROS domain; always terminate it. Yields (process, log)."""
    log = tmp_path / "emulator.jsonl"
    stderr = open(tmp_path / "emulator.stderr", "w")
    process = subprocess.Popen(
        [sys.executable, str(EMULATOR), "--domain", os.environ["ROS_DOMAIN_ID"],
         "--duration", "60", "--log", str(log), *options],
        stdout=subprocess.DEVNULL, stderr=stderr)
    try:
        yield process, log
    finally:
        terminate(process, timeout=5.0)
        stderr.close()
        print((tmp_path / "emulator.stderr").read_text())  # shown if the test failed
        if log.exists():
            print(log.read_text().splitlines()[-1])


def read_log(log: Path) -> list[dict]:
    """The emulator's complete log records so far (a line being written is skipped)."""
    if not log.exists():
        return []
    return [json.loads(line) for line in log.read_text().splitlines() if line.endswith("}")]


def commands_in(log: Path) -> list[dict]:
    """The /cmd_vel commands the emulator received, oldest first."""
    return [record for record in read_log(log) if record["event"] == "cmd"]
