"""Controllers for node tests: importable as tests.controllers:NAME by the `controller` param."""
import math
import os
import signal
import time


class ConstantController:
    """Always commands the same velocities; records what it was given."""

    def __init__(self, dt, v=0.1, w=0.5):
        self.dt, self.v, self.w = dt, v, w
        self.calls = []
        self.geometry = None

    def set_scan_geometry(self, angle_min, angle_increment, range_min, range_max):
        self.geometry = (angle_min, angle_increment, range_min, range_max)

    def compute_commands(self, z_scan, z_v, z_w):
        self.calls.append((len(z_scan), z_v, z_w))
        return self.v, self.w


class NanController(ConstantController):
    def compute_commands(self, z_scan, z_v, z_w):
        return math.nan, math.inf


class HugeController(ConstantController):
    def compute_commands(self, z_scan, z_v, z_w):
        return 50.0, -90.0


class StraightController(ConstantController):
    """Drives straight ahead at 0.2 m/s whatever it sees: it must hit the wall."""

    def __init__(self, dt):
        super().__init__(dt, v=0.2, w=0.0)


class KillsItsProcessOnce:
    """Commands zero; SIGKILLs its own process on its 10th step the first time it runs.

    "The first time" for its `marker` file: a worker lost mid-episode (as the OOM killer or a
    crash would end it); a retry then runs it through.
    """

    def __init__(self, dt, marker=""):
        self.marker, self.calls = marker, 0

    def compute_commands(self, z_scan, z_v, z_w):
        self.calls += 1
        if self.calls == 10 and self.marker and not os.path.exists(self.marker):
            with open(self.marker, "w") as stream:
                stream.write(str(os.getpid()))
            os.kill(os.getpid(), signal.SIGKILL)
        return 0.0, 0.0


class NotesItsProcess:
    """Commands zero; on its first step writes a file named after its process id in `folder`."""

    def __init__(self, dt, folder=""):
        self.folder, self.calls = folder, 0

    def compute_commands(self, z_scan, z_v, z_w):
        self.calls += 1
        if self.calls == 1 and self.folder:
            with open(os.path.join(self.folder, f"{os.getpid()}-{id(self)}"), "w"):
                pass
        return 0.0, 0.0


class Misbehaves:
    """Commands zero; on its 5th step `how`: "none", "sleep" (for good) or "exit" (os._exit(7)).

    With a `marker` path, only the episode that creates that file first misbehaves (the others,
    in parallel workers or after it, run through).
    """

    def __init__(self, dt, how="none", marker=""):
        self.how, self.marker, self.calls = how, marker, 0

    def compute_commands(self, z_scan, z_v, z_w):
        self.calls += 1
        if self.calls == 5 and self.how != "none" and self._first():
            if self.how == "sleep":
                time.sleep(1e6)
            os._exit(7)
        return 0.0, 0.0

    def _first(self) -> bool:
        if not self.marker:
            return True
        try:
            os.close(os.open(self.marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY))
        except FileExistsError:
            return False
        return True
