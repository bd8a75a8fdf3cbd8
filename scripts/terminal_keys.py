"""Keys from a terminal in raw mode (restored on every exit) or from a pipe; a status line.

No rclpy: scripts/teleop.py's keyboard end, testable without ROS.
"""
from __future__ import annotations

import errno
import os
import re
import select
import sys

# ESC [ A..D (ESC O A..D in application mode) are the arrow keys; other escape sequences (with
# modifiers, function keys) are dropped.
_ESCAPE = re.compile(r"\x1b(?:\[([0-9;]*)|O)([A-Za-z~])|\x1b")
_ARROW_NAMES = {"A": "up", "B": "down", "C": "right", "D": "left"}


def keys_in(data: bytes, arrows: dict[str, str] | None = None) -> str:
    """The keys in bytes read from stdin; arrow keys as `arrows` says, line ends dropped."""
    arrows = arrows or {}

    def arrow(match: re.Match) -> str:
        if match.group(1):  # parameters: a modifier such as Ctrl
            return ""
        return arrows.get(_ARROW_NAMES.get(match.group(2) or "", ""), "")

    return _ESCAPE.sub(arrow, data.decode("utf-8", "replace")).replace("\r", "").replace(
        "\n", "")


class KeyReader:
    """Keys from stdin: a terminal in raw mode (restored on exit), or whatever a pipe sends."""

    def __init__(self, arrows: dict[str, str] | None = None, stream=None) -> None:
        """`arrows`: the key each arrow key stands for ('up', 'down', 'left', 'right')."""
        self.arrows = arrows or {}
        stream = sys.stdin if stream is None else stream
        self.fd: int | None = None
        try:
            self.fd = stream.fileno() if stream is not None else None
        except (OSError, ValueError):  # closed or not a real file: no keys will come
            pass
        self.is_tty = self.fd is not None and os.isatty(self.fd)
        self._saved: list | None = None

    def __enter__(self) -> "KeyReader":
        if self.is_tty:
            import termios
            import tty
            self._saved = termios.tcgetattr(self.fd)
            tty.setraw(self.fd, termios.TCSANOW)
            # Raw input (each key at once, Ctrl-C as a key) but normal output: prints keep
            # their line ends.
            mode = termios.tcgetattr(self.fd)
            mode[1] = self._saved[1]
            termios.tcsetattr(self.fd, termios.TCSANOW, mode)
        return self

    def __exit__(self, *exc_info) -> None:
        self.restore()

    def restore(self) -> None:
        """Give the terminal back its settings (once)."""
        if self._saved is not None:
            import termios
            saved, self._saved = self._saved, None
            try:
                termios.tcsetattr(self.fd, termios.TCSADRAIN, saved)
            except termios.error:  # the terminal is gone: nothing left to restore
                pass

    def read(self, timeout: float) -> str | None:
        """The keys typed within `timeout` s ('' if none); None at the end of input."""
        if self.fd is None:
            return None
        ready, _, _ = select.select([self.fd], [], [], max(timeout, 0.0))
        if not ready:
            return ""
        try:
            data = os.read(self.fd, 1024)
        except OSError as exc:
            if exc.errno == errno.EIO:  # the terminal hung up (window closed, ssh dropped)
                return None
            raise
        return keys_in(data, self.arrows) if data else None


class StatusLine:
    """The current command on one line (redrawn on a terminal, one line per change if not).

    Only a display: if the output goes away (a closed pipe, a closed terminal), it stays silent
    and the caller carries on.
    """

    def __init__(self, stream=None) -> None:
        self.stream = sys.stdout if stream is None else stream
        self.redraw = self.stream is not None and self.stream.isatty()
        self._shown: str | None = None

    def show(self, text: str) -> None:
        """Print `text` unless it is already shown."""
        if text != self._shown:
            self._shown = text
            self._write(f"\r\x1b[K{text}" if self.redraw else f"{text}\n")

    def close(self) -> None:
        """End the redrawn line."""
        if self.redraw and self._shown is not None:
            self._write("\n")

    def _write(self, text: str) -> None:
        if self.stream is None:
            return
        try:
            self.stream.write(text)
            self.stream.flush()
        except (OSError, ValueError):  # closed: nobody reads the status any more
            self.stream = None
