"""StopFlag: SIGINT/SIGTERM set a flag that loops poll, instead of raising KeyboardInterrupt.

No rclpy import: a script installs it first thing, so a Ctrl-C during its slow imports and
checks is remembered (and answered with a clean stop) rather than a traceback.
Long computations that cannot see the script's flag (the particle filter's table, built inside
a node's configure) poll `stop_requested()`: true once an installed flag was set.
"""
from __future__ import annotations

import signal

_INSTALLED: list["StopFlag"] = []  # flags between install() and uninstall()


class StopFlag:
    """Set by SIGINT/SIGTERM; spin loops poll it (a blocking spin() would never see a signal)."""

    def __init__(self) -> None:
        self.requested = False
        self._previous: dict[int, object] = {}

    def install(self) -> "StopFlag":
        """Make SIGINT and SIGTERM set this flag; uninstall() restores their handlers."""
        for signum in (signal.SIGINT, signal.SIGTERM):
            self._previous[signum] = signal.signal(signum, self._handle)
        _INSTALLED.append(self)
        return self

    def uninstall(self) -> None:
        """Give SIGINT and SIGTERM back to the handlers they had before install()."""
        for signum, handler in self._previous.items():
            signal.signal(signum, handler)
        self._previous.clear()
        if self in _INSTALLED:
            _INSTALLED.remove(self)

    def _handle(self, signum, frame) -> None:
        self.requested = True


def stop_requested() -> bool:
    """True if a StopFlag installed in this process (and not uninstalled) has been set."""
    return any(flag.requested for flag in _INSTALLED)


__all__ = ["StopFlag", "stop_requested"]
