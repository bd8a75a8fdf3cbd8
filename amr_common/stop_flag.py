"""StopFlag: SIGINT/SIGTERM set a flag that loops poll, instead of raising KeyboardInterrupt.

No rclpy import: a script installs it first thing, so a Ctrl-C during its slow imports and
checks is remembered (and answered with a clean stop) rather than a traceback.
"""
from __future__ import annotations

import signal


class StopFlag:
    """Set by SIGINT/SIGTERM; spin loops poll it (a blocking spin() would never see a signal)."""

    def __init__(self) -> None:
        self.requested = False
        self._previous: dict[int, object] = {}

    def install(self) -> "StopFlag":
        """Make SIGINT and SIGTERM set this flag; uninstall() restores their handlers."""
        for signum in (signal.SIGINT, signal.SIGTERM):
            self._previous[signum] = signal.signal(signum, self._handle)
        return self

    def uninstall(self) -> None:
        """Give SIGINT and SIGTERM back to the handlers they had before install()."""
        for signum, handler in self._previous.items():
            signal.signal(signum, handler)
        self._previous.clear()

    def _handle(self, signum, frame) -> None:
        self.requested = True


__all__ = ["StopFlag"]
