"""Where batch episodes run: this process, a pool of local worker processes, or a Ray cluster.

Every kind of episode (wall following, localization, navigation) is a picklable top-level
function `task(spec) -> outcome` over picklable specs; an executor runs it over a list of specs
and yields `(index, outcome)` as episodes finish, or `(index, TaskLost)` when the process (or
node) that ran an episode died or its result could not come back. `run_tasks` puts the
outcomes back in spec order, calls the progress hook once per finished episode and turns each
TaskLost into the episode kind's own error outcome, so the tables and files do not care where
an episode ran.

- InProcessExecutor: one after the other in this process (a debugger works; nothing protects
  this process from the controller: only for code that asks for it).
- LocalPoolExecutor: worker processes on this machine (the default, also for one episode or
  one job; no Ray needed).
- amr_evaluation.ray_executor.RayExecutor: tasks on a Ray cluster (`evaluate.py --ray`).

The pool and Ray end an episode that runs longer than `episode_timeout_s` of wall-clock time
(a controller that sleeps or loops forever) with its worker process, and report it as that
episode's TaskLost; a new worker takes the episodes left (episode_time_limit() is the default
evaluate.py and tune.py give).
"""
from __future__ import annotations

import importlib
import multiprocessing
import os
import signal
import time
from dataclasses import dataclass
from multiprocessing.connection import Connection, wait
from typing import Any, Callable, Iterator, Protocol, Sequence

__all__ = ["TaskLost", "Executor", "InProcessExecutor", "LocalPoolExecutor", "local_executor",
           "run_tasks", "episode_time_limit", "timed_out"]

Task = Callable[[Any], Any]
_STARTED = "amr_evaluation.executors.STARTED"  # a worker's note: the episode it got began


def episode_time_limit(duration_s: float) -> float:
    """The default wall-clock limit of an episode of `duration_s` simulated seconds.

    The larger of 60 s and twice the simulated time: episodes run tens to thousands of times
    faster than real time, so only a controller that hangs (or a machine far too loaded)
    reaches it.
    """
    return max(60.0, 2.0 * float(duration_s))


def timed_out(limit_s: float, wall_time_s: float) -> "TaskLost":
    """The TaskLost of an episode ended at its wall-clock limit."""
    return TaskLost(f"the episode ran past its wall-clock limit of {limit_s:g} s "
                    "(--episode-timeout) and its worker process was ended: a controller that "
                    "hangs or sleeps, or an episode far slower than its simulated time",
                    wall_time_s)


def _check_limit(episode_timeout_s: float | None) -> float | None:
    """None or 0: no limit; else a positive number of seconds (ValueError otherwise)."""
    if episode_timeout_s is None or episode_timeout_s == 0:
        return None
    limit = float(episode_timeout_s)
    if not limit > 0 or limit == float("inf"):
        raise ValueError(f"the episode timeout must be a number of seconds > 0 (0: no limit), "
                         f"got {episode_timeout_s!r}")
    return limit


@dataclass(frozen=True)
class TaskLost:
    """An episode whose process or node died, or whose result could not be sent back."""

    error: str
    wall_time_s: float = 0.0


class Executor(Protocol):
    """Runs `task` over `specs`, yielding (index, outcome or TaskLost) as episodes finish."""

    def describe(self) -> str:
        """Where the episodes run, for the start-up line and results.json."""

    def workers(self, episodes: int) -> int:
        """How many episodes run at once."""

    def run(self, task: Task, specs: Sequence[Any],
            preload: Sequence[str] = ()) -> Iterator[tuple[int, Any]]:
        """Yield (index into specs, outcome or TaskLost), each index exactly once."""


def run_tasks(task: Task, specs: Sequence[Any], executor: Executor,
              lost: Callable[[Any, TaskLost], Any],
              progress: Callable[[int, int, Any], None] | None = None,
              preload: Sequence[str] = ()) -> list[Any]:
    """Run `task` over `specs` on `executor`; outcomes in spec order.

    `lost(spec, TaskLost)` builds the error outcome of an episode whose process died;
    `progress(done, total, outcome)` is called once per finished episode; `preload` names
    modules the workers import once before their first episode (compiled kernels).
    """
    specs = list(specs)
    outcomes: list[Any] = [None] * len(specs)
    finished = [False] * len(specs)
    done = 0
    for index, outcome in executor.run(task, specs, preload):
        if finished[index]:
            continue  # an executor must not report an episode twice; ignore it if it does
        if isinstance(outcome, TaskLost):
            outcome = lost(specs[index], outcome)
        outcomes[index], finished[index] = outcome, True
        done += 1
        if progress:
            progress(done, len(specs), outcome)
    return outcomes


class InProcessExecutor:
    """Runs the episodes one after the other in this process."""

    def describe(self) -> str:
        """'this process'."""
        return "this process"

    def workers(self, episodes: int) -> int:
        """One at a time."""
        return 1

    def run(self, task: Task, specs: Sequence[Any],
            preload: Sequence[str] = ()) -> Iterator[tuple[int, Any]]:
        """Yield each episode's outcome in spec order."""
        for index, spec in enumerate(specs):
            yield index, task(spec)


class LocalPoolExecutor:
    """Worker processes on this machine that each run one episode at a time.

    Unlike multiprocessing.Pool (which waits forever for the task of a worker that died), a
    worker that ends during an episode (os._exit, a crash, the OOM killer) makes that
    episode's TaskLost, and so does an episode past `episode_timeout_s` of wall-clock time
    (its worker is killed); a new worker takes the remaining episodes.
    """

    def __init__(self, jobs: int | None = None,
                 episode_timeout_s: float | None = None) -> None:
        self.jobs = (os.cpu_count() or 1) if jobs is None else int(jobs)
        if self.jobs < 1:
            raise ValueError(f"jobs must be >= 1, got {self.jobs}")
        self.episode_timeout_s = _check_limit(episode_timeout_s)

    def describe(self) -> str:
        """'N local process(es)'."""
        return f"{self.jobs} local process(es)"

    def workers(self, episodes: int) -> int:
        """At most one process per episode."""
        return max(1, min(self.jobs, episodes))

    def run(self, task: Task, specs: Sequence[Any],
            preload: Sequence[str] = ()) -> Iterator[tuple[int, Any]]:
        """Yield (index, outcome or TaskLost) as the workers finish episodes."""
        if not specs:
            return
        yield from _WorkerPool(task, specs, self.workers(len(specs)), tuple(preload),
                               self.episode_timeout_s).run()


def local_executor(jobs: int | None, episodes: int | None = None,
                   episode_timeout_s: float | None = None) -> LocalPoolExecutor:
    """A pool of `jobs` worker processes (None: all cores), at most one per episode.

    Also for one job or one episode: a controller that hangs or ends its process must not
    take this process (the driver, holding the other episodes' results) with it.
    ValueError for jobs < 1 or a bad timeout.
    """
    return LocalPoolExecutor(jobs, episode_timeout_s)


# --- the local pool ------------------------------------------------------------------------

def _preload(modules: Sequence[str]) -> None:
    for name in modules:
        try:
            importlib.import_module(name)
        except Exception:  # noqa: BLE001 - the episode imports it again and reports the error
            pass


def _context(preload: Sequence[str]) -> multiprocessing.context.BaseContext:
    # forkserver, else spawn: no fork of a parent that may hold threads. Workers import the
    # episode modules and their numba kernels once (preload) and then run many episodes.
    if "forkserver" in multiprocessing.get_all_start_methods():
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(list(preload))
        return ctx
    return multiprocessing.get_context("spawn")


def _worker_main(connection: Connection, task: Task, preload: Sequence[str]) -> None:
    """A worker process: runs each (index, spec) it receives until it receives None."""
    # Ctrl-C and a closed terminal's SIGHUP go to the whole process group: only the parent
    # handles them (and ends the pool).
    for signum in (signal.SIGINT, getattr(signal, "SIGHUP", None)):
        if signum is not None:
            signal.signal(signum, signal.SIG_IGN)
    _preload(preload)
    while True:
        try:
            item = connection.recv()
        except EOFError:  # the parent went away
            return
        if item is None:
            return
        index, spec = item
        started = time.perf_counter()
        connection.send((index, _STARTED))  # the episode's clock starts now (not at import)
        outcome = task(spec)
        try:
            connection.send((index, outcome))
        except Exception as exc:  # e.g. a result that cannot be pickled
            connection.send((index, TaskLost(f"the result could not be sent back: {exc!r}",
                                             time.perf_counter() - started)))


class _WorkerPool:
    def __init__(self, task: Task, specs: Sequence[Any], workers: int,
                 preload: tuple[str, ...], limit_s: float | None = None) -> None:
        self._task, self._preload = task, preload
        self._context = _context(preload)
        self._pending = list(enumerate(specs))[::-1]  # popped from the end: spec order
        self._workers = workers
        self._limit_s = limit_s
        # connection -> [process, index of the episode it runs or None, time it was sent,
        # time the worker began it or None]
        self._running: dict[Connection, list] = {}

    def run(self) -> Iterator[tuple[int, Any]]:
        try:
            for _ in range(self._workers):
                self._start_worker()
            while self._running:
                by_sentinel = {entry[0].sentinel: conn for conn, entry in self._running.items()}
                for ready in wait([*self._running, *by_sentinel], timeout=self._next_deadline()):
                    conn = by_sentinel.get(ready, ready)
                    if conn in self._running:
                        yield from self._collect(conn)
                yield from self._end_overdue()
        finally:
            for conn, (process, *_) in list(self._running.items()):
                process.terminate()
                process.join(timeout=5.0)
                conn.close()
            self._running.clear()

    def _start_worker(self) -> None:
        ours, theirs = self._context.Pipe()
        process = self._context.Process(target=_worker_main,
                                        args=(theirs, self._task, self._preload), daemon=True)
        process.start()
        theirs.close()
        self._running[ours] = [process, None, 0.0, None]
        self._assign(ours)

    def _next_deadline(self) -> float | None:
        """Seconds until the first running episode reaches the limit (None: no limit)."""
        begun = [entry[3] for entry in self._running.values() if entry[3] is not None]
        if self._limit_s is None or not begun:
            return None
        return max(0.0, min(begun) + self._limit_s - time.perf_counter())

    def _end_overdue(self) -> Iterator[tuple[int, Any]]:
        """Kill the workers whose episode ran past the limit: the episodes' TaskLost."""
        if self._limit_s is None:
            return
        now = time.perf_counter()
        for conn, (process, index, _, begun) in list(self._running.items()):
            if begun is None or now - begun < self._limit_s or conn.poll():
                continue  # in time, or its result is here already
            process.kill()  # SIGKILL: a hung controller may ignore anything else
            process.join(timeout=5.0)
            del self._running[conn]
            conn.close()
            yield index, timed_out(self._limit_s, now - begun)
            if self._pending:
                self._start_worker()

    def _assign(self, conn: Connection) -> None:
        entry = self._running[conn]
        if not self._pending:
            entry[1] = None
            try:
                conn.send(None)  # nothing left: the worker exits
            except OSError:
                pass
            return
        index, spec = self._pending.pop()
        entry[1:] = [index, time.perf_counter(), None]
        conn.send((index, spec))

    def _collect(self, conn: Connection) -> Iterator[tuple[int, Any]]:
        process, index, started, _ = self._running[conn]
        try:
            if conn.poll():
                result_index, outcome = conn.recv()
                if isinstance(outcome, str) and outcome == _STARTED:
                    self._running[conn][3] = time.perf_counter()
                    return
                yield result_index, outcome
                self._assign(conn)
                return
            if process.is_alive():
                return  # a spurious wake-up
        except (EOFError, OSError):
            pass  # its end of the pipe closed: the worker is gone or going
        process.join(timeout=5.0)
        if process.is_alive():  # closed its pipe but did not exit
            process.terminate()
            process.join(timeout=5.0)
        del self._running[conn]
        conn.close()
        if index is not None:
            code = process.exitcode
            how = f"killed by signal {-code}" if code is not None and code < 0 else \
                f"exit code {code}"
            yield index, TaskLost(
                f"worker process died ({how}) during this episode: the controller or the "
                f"simulator ended the process (os._exit, a crash, out of memory)",
                time.perf_counter() - started)
            if self._pending:
                self._start_worker()
