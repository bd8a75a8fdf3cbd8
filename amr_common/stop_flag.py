"""StopFlag: SIGINT, SIGTERM and SIGHUP set a flag that loops poll; it remembers which came.

No rclpy import: a script installs it first thing, so a Ctrl-C during its slow imports and
checks is remembered (and answered with a clean stop) rather than a traceback. SIGHUP (the
terminal closed, the SSH session dropped) is a stop like the others: the robot's firmware has no
command timeout, so a run must still send its zero command and write what it has.
Scripts that answer a stop by unwinding (KeyboardInterrupt, as Ctrl-C does by default) install
it with `raise_interrupt=True`; either way `exit_code` says which signal came.
Long computations that cannot see the script's flag (the particle filter's table, built inside
a node's configure) poll `stop_requested()`: true once an installed flag was set.
"""
from __future__ import annotations

import signal

# The signals that stop a run, where the platform has them (Windows has no SIGHUP).
STOP_SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP")
                     if hasattr(signal, name))
INTERRUPTED = 130  # exit code after Ctrl-C or SIGTERM (128 + SIGINT, as a shell reports Ctrl-C)
HUNG_UP = 129  # exit code after SIGHUP (128 + SIGHUP)
_INSTALLED: list["StopFlag"] = []  # flags between install() and uninstall()


def exit_code_after(signum: int | None) -> int:
    """The exit code of a run stopped by `signum`: 129 after SIGHUP, else 130."""
    return HUNG_UP if signum is not None and signum == getattr(signal, "SIGHUP", None) \
        else INTERRUPTED


class StopFlag:
    """Set by SIGINT/SIGTERM/SIGHUP; spin loops poll it (a blocking spin() never sees a signal).

    `signum`: the first signal that came (None: none, or the flag was set by the program).
    With `raise_interrupt`, each of them also raises KeyboardInterrupt, as Ctrl-C does.
    """

    def __init__(self, raise_interrupt: bool = False) -> None:
        self.requested = False
        self.signum: int | None = None
        self.raise_interrupt = raise_interrupt
        self._previous: dict[int, object] = {}

    def install(self) -> "StopFlag":
        """Make the stop signals set this flag; uninstall() restores their handlers."""
        for signum in STOP_SIGNALS:
            self._previous[signum] = signal.signal(signum, self._handle)
        _INSTALLED.append(self)
        return self

    def uninstall(self) -> None:
        """Give the stop signals back to the handlers they had before install()."""
        for signum, handler in self._previous.items():
            signal.signal(signum, handler)
        self._previous.clear()
        if self in _INSTALLED:
            _INSTALLED.remove(self)

    @property
    def exit_code(self) -> int:
        """130 after Ctrl-C or SIGTERM, 129 after SIGHUP (the shell's 128 + signal number)."""
        return exit_code_after(self.signum)

    def _handle(self, signum, frame) -> None:
        if self.signum is None:
            self.signum = signum
        self.requested = True
        if self.raise_interrupt:
            raise KeyboardInterrupt


def stop_requested() -> bool:
    """True if a StopFlag installed in this process (and not uninstalled) has been set."""
    return any(flag.requested for flag in _INSTALLED)


__all__ = ["HUNG_UP", "INTERRUPTED", "STOP_SIGNALS", "StopFlag", "exit_code_after",
           "stop_requested"]
