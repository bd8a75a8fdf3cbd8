"""Helpers for tests that run project executables as separate processes."""
from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path
from typing import Callable

import pytest


def wait_for(condition: Callable[[], bool], timeout: float, what: str,
             poll: float = 0.05) -> None:
    """Poll condition() until it is true; fail the test after `timeout` seconds."""
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            pytest.fail(f"timed out after {timeout} s waiting for {what}")
        time.sleep(poll)


REPO = Path(__file__).resolve().parent.parent


def run_script_while_spinning(ros, *args: str, timeout: float = 20.0) -> str:
    """Run `python <args>` from the repository root while the `ros` fixture's nodes spin.

    Fails the test on a non-zero exit; returns the standard output.
    """
    process = subprocess.Popen([sys.executable, *args], stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True, cwd=REPO)
    try:
        ros.spin_until(lambda: process.poll() is not None, timeout=timeout,
                       message=f"{' '.join(args)} to finish")
    finally:
        terminate(process, 2.0)
    out, err = process.communicate()
    assert process.returncode == 0, err
    return out


def terminate(process: subprocess.Popen, timeout: float) -> None:
    """SIGTERM the process if it still runs; SIGKILL it if it has not exited after `timeout`."""
    if process.poll() is not None:
        return
    process.terminate()
    try:
        process.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait()
