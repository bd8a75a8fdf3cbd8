"""Where batch episodes run: this process, a pool of local worker processes, or a Ray cluster.

Every kind of episode (wall following, localization, navigation) is a picklable top-level
function `task(spec) -> outcome` over picklable specs; an executor runs it over a list of specs
and yields `(index, outcome)` as episodes finish, or `(index, TaskLost)` when the process (or
node) that ran an episode died or its result could not come back. `run_tasks` puts the
outcomes back in spec order, calls the progress hook once per finished episode and turns each
TaskLost into the episode kind's own error outcome, so the tables and files do not care where
an episode ran.

- InProcessExecutor: one after the other in this process (jobs=1; a debugger works).
- LocalPoolExecutor: worker processes on this machine (the default; no Ray needed).
- amr_evaluation.ray_executor.RayExecutor: tasks on a Ray cluster (`evaluate.py --ray`).
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
           "run_tasks"]

Task = Callable[[Any], Any]


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
    episode's TaskLost; a new worker takes the remaining episodes.
    """

    def __init__(self, jobs: int | None = None) -> None:
        self.jobs = (os.cpu_count() or 1) if jobs is None else int(jobs)
        if self.jobs < 1:
            raise ValueError(f"jobs must be >= 1, got {self.jobs}")

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
        yield from _WorkerPool(task, specs, self.workers(len(specs)), tuple(preload)).run()


def local_executor(jobs: int | None,
                   episodes: int | None = None) -> InProcessExecutor | LocalPoolExecutor:
    """This process for jobs=1 or at most one episode, else a pool of `jobs` processes.

    jobs None: all cores; ValueError for jobs < 1 (checked in every case).
    """
    pool = LocalPoolExecutor(jobs)
    return InProcessExecutor() if pool.jobs == 1 or (episodes is not None and episodes <= 1) \
        else pool


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
    # Ctrl-C goes to the whole process group: only the parent handles it (and ends the pool).
    signal.signal(signal.SIGINT, signal.SIG_IGN)
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
        outcome = task(spec)
        try:
            connection.send((index, outcome))
        except Exception as exc:  # e.g. a result that cannot be pickled
            connection.send((index, TaskLost(f"the result could not be sent back: {exc!r}",
                                             time.perf_counter() - started)))


class _WorkerPool:
    def __init__(self, task: Task, specs: Sequence[Any], workers: int,
                 preload: tuple[str, ...]) -> None:
        self._task, self._preload = task, preload
        self._context = _context(preload)
        self._pending = list(enumerate(specs))[::-1]  # popped from the end: spec order
        self._workers = workers
        # connection -> [process, index of the episode it runs or None, start time]
        self._running: dict[Connection, list] = {}

    def run(self) -> Iterator[tuple[int, Any]]:
        try:
            for _ in range(self._workers):
                self._start_worker()
            while self._running:
                by_sentinel = {entry[0].sentinel: conn for conn, entry in self._running.items()}
                for ready in wait([*self._running, *by_sentinel]):
                    conn = by_sentinel.get(ready, ready)
                    if conn in self._running:
                        yield from self._collect(conn)
        finally:
            for conn, (process, _, _) in list(self._running.items()):
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
        self._running[ours] = [process, None, 0.0]
        self._assign(ours)

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
        entry[1], entry[2] = index, time.perf_counter()
        conn.send((index, spec))

    def _collect(self, conn: Connection) -> Iterator[tuple[int, Any]]:
        process, index, started = self._running[conn]
        try:
            if conn.poll():
                result_index, outcome = conn.recv()
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
