"""How a user command ends: a closed output or a stop signal loses none of its results.

Closed output (`| head`, `| tee log` then Ctrl-C, a closed terminal): every script's `__main__`
runs its main through `run_script`, which guards sys.stdout and sys.stderr. The first write or
flush that fails (EPIPE: the reader is gone; EIO: the terminal hung up; ENOSPC ...) points that
stream's file descriptor at os.devnull (the C logging of the nodes included) and the text is
dropped. Nothing raises where the script prints: a run goes on, writes its report, plot and map,
and ends with its own exit code; no traceback, no "Exception ignored ... BrokenPipeError" at
exit. It is the usual Python idiom (catch BrokenPipeError, point stdout at devnull) applied at
every print instead of around main: a BrokenPipeError unwinding a run would lose what it has not
written yet. Commands whose output is all they do (topic.py echo and hz) poll `stdout_closed()`
and end with OUTPUT_CLOSED, as `yes | head` does.

Stop signals: the run scripts poll an amr_common.stop_flag.StopFlag (Ctrl-C, SIGTERM, SIGHUP);
the batch scripts that unwind on Ctrl-C (evaluate, tune, slam_round_trip, calibrate_lidar) run
through `interruptible`, so SIGTERM and SIGHUP (the terminal closed) unwind them too, with the
exit code of the signal that came.
"""
from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Callable, TextIO

REPO = Path(__file__).resolve().parent.parent
if str(REPO) not in sys.path:  # run from a checkout without installing
    sys.path.insert(0, str(REPO))

from amr_common.stop_flag import StopFlag  # noqa: E402

OUTPUT_CLOSED = 141  # exit code of a command ended by its closed output: 128 + SIGPIPE


class GuardedStream:
    """A text stream whose write and flush never raise once its reader has gone away.

    `lost` is True from the first failure on; the file descriptor then writes to os.devnull.
    Everything else (fileno, isatty, encoding, ...) is the wrapped stream's.
    """

    def __init__(self, stream: TextIO) -> None:
        self.stream = stream
        self.lost = False

    def write(self, text: str) -> int:
        try:
            return self.stream.write(text)
        except BlockingIOError:  # a full non-blocking pipe: not a closed one
            raise
        except (OSError, ValueError):  # ValueError: the stream itself was closed
            self._lose()
            return len(text)

    def writelines(self, lines) -> None:
        for line in lines:
            self.write(line)

    def flush(self) -> None:
        try:
            self.stream.flush()
        except BlockingIOError:
            raise
        except (OSError, ValueError):
            self._lose()

    def _lose(self) -> None:
        """The output is gone: write to os.devnull from now on (the buffered text too)."""
        self.lost = True
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            try:
                os.dup2(devnull, self.stream.fileno())
            finally:
                os.close(devnull)
            self.stream.flush()  # what the failed write left in the buffer, to devnull
        except (OSError, ValueError):
            pass

    def __getattr__(self, name: str):
        return getattr(self.stream, name)


def guard_output() -> None:
    """Guard sys.stdout and sys.stderr (see the module docstring); a second call does nothing."""
    for name in ("stdout", "stderr"):
        stream = getattr(sys, name)
        if stream is not None and not isinstance(stream, GuardedStream):
            setattr(sys, name, GuardedStream(stream))


def stdout_closed() -> bool:
    """True once a write to the guarded stdout failed: nobody reads the output any more."""
    return bool(getattr(sys.stdout, "lost", False))


def run_script(main: Callable[[], int | None]) -> int | None:
    """A script's main with its outputs guarded: its exit code, for sys.exit()."""
    guard_output()
    code = main()
    sys.stdout.flush()  # a closed pipe shows here at the latest, not in Python's exit
    return code


def interruptible(message: str, run: Callable[[], int]) -> int:
    """run() with SIGTERM and SIGHUP unwinding it as Ctrl-C does (a KeyboardInterrupt).

    After any of them: `message` on stderr and the exit code 130 (Ctrl-C, SIGTERM) or 129
    (SIGHUP).
    """
    stop = StopFlag(raise_interrupt=True).install()
    try:
        return run()
    except KeyboardInterrupt:
        print(message, file=sys.stderr)
        return stop.exit_code
    finally:
        stop.uninstall()


__all__ = ["OUTPUT_CLOSED", "GuardedStream", "guard_output", "interruptible", "run_script",
           "stdout_closed"]
