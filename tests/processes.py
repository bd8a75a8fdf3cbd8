"""Helpers for tests that run project executables as separate processes."""
from __future__ import annotations

import subprocess
import time
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
