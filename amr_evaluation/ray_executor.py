"""Episodes on Ray: on a local Ray instance started here, or on a running Ray cluster.

    with RayExecutor() as executor:              # a local instance on 127.0.0.1, stopped after
        outcomes = run_episodes(specs, executor=executor)
    with RayExecutor("auto") as executor:        # the cluster this machine belongs to
        ...

Needs the optional `cluster` extra (`pip install -e .[cluster]`, or requirements-cluster.lock);
nothing else in the project imports Ray. Every node's workers must import this project from the
same venv path (or a runtime_env that installs it): see docs/tune.md, "Sweep on a cluster".

Episodes run on EpisodeWorker actors of 1 CPU each (amr_evaluation/ray_workers.py), one
episode at a time per worker, as many workers as the cluster has CPUs. Joining a running
cluster, the workers are warm: they stay `keep_workers_s` (60 s) after the run, imported and
ready for the next run from the same checkout, and never run code older than the files. An
episode whose worker process or node died is run once more (RETRIES) on another worker; a
second loss, or an error Ray raises for the task (its arguments could not be unpickled on the
worker, ...), becomes that episode's TaskLost with the reason. While no node with a CPU is
alive for `no_worker_timeout_s`, the episodes left are reported lost instead of waiting
forever. Exceptions inside an episode are its own error outcome already (run_one), never
retried: episodes are deterministic. An episode running longer than `episode_timeout_s` of
wall-clock time (a controller that hangs) is not retried either: its worker is killed and
replaced, and the episode's TaskLost says why.
"""
from __future__ import annotations

import logging
import math
import os
import time
import traceback
from collections import deque
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping, Sequence

from amr_evaluation.executors import TaskLost, _check_limit, timed_out
from amr_evaluation.ray_pool import WorkerLost, WorkerSet, import_hint, two_lines
from amr_evaluation.ray_workers import (
    STALE,
    EpisodeWorker,
    release_idle_warm_workers,
    worker_key,
)

__all__ = ["RayExecutor", "RaySetupError", "LOCAL_RAY_ENV"]

# A Ray instance started here: usage statistics off, every Ray process bound to 127.0.0.1
# (with the loopback address as node IP, Ray's servers listen on it alone), token
# authentication as Ray's default for a new local instance but stated, so Ray does not warn.
# Read by Ray at import: set before the first `import ray` of the process (connect() does).
LOCAL_RAY_ENV = {"RAY_USAGE_STATS_ENABLED": "0", "RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER": "0",
                 "RAY_AUTH_MODE": "token"}
RETRIES = 1
QUEUED = 2  # episodes sent ahead to each worker


class RaySetupError(RuntimeError):
    """Ray is missing or the cluster cannot be reached; the message says which and what to do."""


def _on_loopback(address: str) -> bool:
    """Whether the cluster at `address` ("auto": this machine's) has its head on 127.0.0.1.

    A driver looks for a Ray node of its own IP; on a cluster bound to the loopback address it
    must take 127.0.0.1 as its IP too, or it waits for a node that never comes.
    """
    if address == "auto":
        address = os.environ.get("RAY_ADDRESS", "")
        if not address:  # where `ray start` and ray.init note the running cluster
            import tempfile
            noted = Path(os.environ.get("RAY_TMPDIR", tempfile.gettempdir()), "ray",
                         "ray_current_cluster")
            try:
                address = noted.read_text(encoding="utf-8").strip()
            except OSError:
                return False
    host = address.split("://")[-1].rsplit(":", 1)[0].strip("[]")
    return host in ("127.0.0.1", "localhost", "::1")


class RayExecutor:
    """Runs episode tasks on Ray: a local instance (address None) or a running cluster.

    `address`: None starts a local instance with `num_cpus` CPUs (default: all cores), bound to
    127.0.0.1, without dashboard; "auto" joins the cluster this machine is a node of; HOST:PORT
    joins the cluster whose head listens there; "ray://HOST:10001" connects through Ray Client.
    If this process is already connected to Ray (ray.init), that connection is used and left
    open. `runtime_env`: Ray's runtime environment for the workers (e.g. a wheel of the
    project in py_modules). `keep_workers_s`: on a cluster joined (an address), how long the
    workers stay idle after a run for the next one (0: they end with the run).
    `episode_timeout_s`: the wall-clock limit of one episode (None or 0: none).
    """

    def __init__(self, address: str | None = None, num_cpus: int | None = None,
                 runtime_env: Mapping[str, Any] | None = None,
                 no_worker_timeout_s: float = 60.0, keep_workers_s: float = 60.0,
                 episode_timeout_s: float | None = None) -> None:
        self.address = address or None
        self.num_cpus = num_cpus
        self.runtime_env = dict(runtime_env) if runtime_env else None
        self.no_worker_timeout_s = float(no_worker_timeout_s)
        self.episode_timeout_s = _check_limit(episode_timeout_s)
        if not math.isfinite(keep_workers_s) or keep_workers_s < 0:
            raise ValueError(f"keep_workers_s must be a finite number >= 0, got "
                             f"{keep_workers_s}")
        # Warm workers only on a cluster that outlives this run (not an instance started here).
        self.keep_workers_s = float(keep_workers_s) if self.address else 0.0
        self._ray: Any = None
        self._owned = False
        self._worker_class: Any = None
        self._workers: WorkerSet | None = None

    # --- connection ----------------------------------------------------------------------

    def __enter__(self) -> "RayExecutor":
        self.connect()
        return self

    def __exit__(self, *exc_info: Any) -> None:
        self.close()

    def connect(self) -> None:
        """Start or join the cluster (once); RaySetupError with a reason on failure."""
        if self._ray is not None:
            return
        if self.address is None:
            for name, value in LOCAL_RAY_ENV.items():
                os.environ.setdefault(name, value)
        else:
            os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
            if _on_loopback(self.address):  # this driver's node is 127.0.0.1 too
                os.environ.setdefault("RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER", "0")
        try:
            import ray
        except ImportError as exc:
            raise RaySetupError(f"Ray is not installed ({exc}): install the cluster extra, "
                                "`.venv/bin/pip install -r requirements-cluster.lock` (make "
                                "test does)") from None
        if ray.is_initialized():
            self._ray, self._owned = ray, False
        else:
            kwargs: dict[str, Any] = {"logging_level": logging.WARNING,
                                      "runtime_env": self.runtime_env}
            if self.address is None:
                kwargs.update(address="local", num_cpus=self.num_cpus or os.cpu_count() or 1,
                              include_dashboard=False)
            else:
                kwargs.update(address=self.address)
            try:
                ray.init(**kwargs)
            except Exception as exc:  # ConnectionError, ValueError, RuntimeError, ...
                detail = traceback.format_exception_only(type(exc), exc)[-1].strip()
                where = "start a local Ray instance" if self.address is None else \
                    f"connect to the Ray cluster at '{self.address}'"
                hint = "" if self.address is None or os.environ.get("RAY_AUTH_MODE") else (
                    " (a cluster with token authentication needs RAY_AUTH_MODE=token and its "
                    "token in ~/.ray/auth_token or RAY_AUTH_TOKEN)")
                raise RaySetupError(f"cannot {where}: {' '.join(detail.split())}{hint}") \
                    from None
            self._ray, self._owned = ray, True
        self._worker_class = self._ray.remote(
            num_cpus=1, max_restarts=0, max_task_retries=0,
            concurrency_groups={"control": 1})(EpisodeWorker)
        if self.address:  # idle warm workers this run does not use free their CPUs
            release_idle_warm_workers(
                self._ray, keep_key=worker_key(self.runtime_env) if self.keep_workers_s else None)

    def close(self) -> None:
        """End the workers (warm ones stay), stop the local instance started here, or leave."""
        if self._workers is not None:
            self._workers.leave()
            self._workers = None
        if self._ray is not None and self._owned:
            self._ray.shutdown()
        self._ray, self._owned, self._worker_class = None, False, None

    def cluster_cpus(self) -> int:
        """CPUs of the cluster's alive nodes."""
        self.connect()
        return int(self._ray.cluster_resources().get("CPU", 0))

    def describe(self) -> str:
        """'Ray at ADDRESS: N CPUs on M node(s)'."""
        self.connect()
        nodes = sum(1 for node in self._ray.nodes() if node.get("Alive"))
        where = "a local Ray instance" if self._owned and self.address is None else \
            f"the Ray cluster at {self._ray.get_runtime_context().gcs_address}"
        return f"{where}: {self.cluster_cpus()} CPUs on {nodes} node(s)"

    def workers(self, episodes: int) -> int:
        """Episodes that can run at once: the cluster's CPUs (each worker takes one)."""
        return max(1, min(self.cluster_cpus(), episodes))

    # --- running -------------------------------------------------------------------------

    def run(self, task: Callable[[Any], Any], specs: Sequence[Any],
            preload: Sequence[str] = ()) -> Iterator[tuple[int, Any]]:
        """Yield (index, outcome or TaskLost) as episodes finish.

        Workers are those of an earlier run with this key (warm) plus new ones up to the
        cluster's CPUs (checked every 2 s: nodes come and go). While many are left, each has
        QUEUED episodes sent ahead, so the next one starts without a round trip to this
        driver. An episode whose worker died is run once more (RETRIES); one whose worker's
        code changed on disk, or that waited behind a lost one, is run again without counting.
        """
        self.connect()
        if self._workers is None:  # kept for later runs of this executor (close() ends them)
            self._workers = WorkerSet(self)
        pool = self._workers
        pool.new_run(tuple(preload))
        waiting = deque(enumerate(specs))
        tries = [0] * len(specs)
        running: dict[Any, tuple[Any, int, float]] = {}  # ref -> (worker, index, submitted)
        queues: dict[Any, deque] = {}  # worker's actor id -> its refs, in submission order
        begun: dict[Any, float] = {}  # ref -> when the driver saw it start (first in queue)
        no_cpu_since: float | None = None
        try:
            while waiting or running:
                yield from self._end_overdue(running, queues, begun, waiting, specs)
                pool.top_up(len(waiting) + len(running))
                # Sent ahead only while there is plenty left: the last ones go to whichever
                # worker is free first, and a worker still starting gets its share.
                members = len(pool.ready) + len(pool.starting)
                depth = QUEUED if len(waiting) > QUEUED * members else 1
                self._submit(task, pool, depth, waiting, running, queues)
                ready, _ = self._ray.wait([*running, *pool.starting], num_returns=1,
                                          timeout=1.0, fetch_local=False)
                if ready:  # and every other one finished by now
                    ready, _ = self._ray.wait([*running, *pool.starting],
                                              num_returns=len(running) + len(pool.starting),
                                              timeout=0, fetch_local=False)
                for ref in ready:
                    if ref in pool.starting:
                        pool.started(ref)
                    elif ref in running:  # else it waited behind a lost one: queued again
                        yield from self._finished(ref, pool, running, queues, tries, specs,
                                                  waiting)
                if pool.failure and not pool.ready and not pool.starting and not running:
                    for index, _ in waiting:  # no worker can be created: say why, do not wait
                        yield index, TaskLost(pool.failure)
                    waiting.clear()
                if ready or pool.ready or self.cluster_cpus() > 0:
                    no_cpu_since = None
                    continue
                no_cpu_since = no_cpu_since or time.monotonic()
                if time.monotonic() - no_cpu_since >= self.no_worker_timeout_s:
                    yield from self._lose_all(running, queues, waiting)
        finally:
            for ref in running:  # interrupted (Ctrl-C, an exception in the consumer)
                try:
                    self._ray.cancel(ref)
                except Exception:  # noqa: BLE001 - best effort while leaving
                    pass

    def _submit(self, task: Callable[[Any], Any], pool: WorkerSet, depth: int, waiting: deque,
                running: dict, queues: dict) -> None:
        """Fill each ready worker's queue up to `depth` episodes."""
        for worker in pool.ready:
            queue = queues.setdefault(worker._actor_id, deque())
            while waiting and len(queue) < depth:
                index, spec = waiting.popleft()
                ref = worker.run.remote(task, pool.preload, spec)
                running[ref] = (worker, index, time.perf_counter())
                queue.append(ref)

    def _finished(self, ref: Any, pool: WorkerSet, running: dict, queues: dict,
                  tries: list[int], specs: Sequence[Any],
                  waiting: deque) -> Iterator[tuple[int, Any]]:
        """A finished ref: its outcome; or its worker was lost: its queue retried or lost."""
        worker, index, submitted = running.pop(ref)
        outcome = self._fetch(ref, time.perf_counter() - submitted)
        if not isinstance(outcome, WorkerLost):
            queues[worker._actor_id].remove(ref)
            yield index, outcome
            return
        # The worker ran its queue in order: the first one was running when it ended (one
        # try), the others never started.
        pool.discard(worker)
        again = []
        for k, lost_ref in enumerate(queues.pop(worker._actor_id)):
            _, lost_index, _ = running.pop(lost_ref, (None, index, None))
            if k == 0 and not outcome.code_changed:
                tries[lost_index] += 1
                if tries[lost_index] > RETRIES:
                    yield lost_index, TaskLost(outcome.why(pool, worker, tries[lost_index]),
                                               outcome.wall_time_s)
                    continue
            again.append((lost_index, specs[lost_index]))
        waiting.extendleft(reversed(again))

    def _lose_all(self, running: dict, queues: dict,
                  waiting: deque) -> Iterator[tuple[int, Any]]:
        """No node with a CPU for no_worker_timeout_s: every episode left is lost, said why."""
        lost = (f"no Ray node with a CPU was alive for {self.no_worker_timeout_s:g} s (the "
                "cluster lost its worker nodes): the episode did not run")
        for ref, (worker, index, submitted) in list(running.items()):
            yield index, TaskLost(lost, time.perf_counter() - submitted)
        running.clear()
        queues.clear()
        while waiting:
            yield waiting.popleft()[0], TaskLost(lost)

    def _end_overdue(self, running: dict, queues: dict, begun: dict, waiting: deque,
                     specs: Sequence[Any]) -> Iterator[tuple[int, Any]]:
        """Kill and replace the workers whose episode ran past the limit: its TaskLost.

        A worker runs its queue in order: the first of its refs is running, since the driver
        saw the one before end (the clock starts then, within a loop turn of ~1 s at most).
        The episodes queued behind it never started: they are run again elsewhere.
        """
        if self.episode_timeout_s is None:
            return
        now = time.perf_counter()
        for actor, queue in list(queues.items()):
            if not queue or queue[0] not in running:
                continue
            head = queue[0]
            since = begun.setdefault(head, now)
            if now - since < self.episode_timeout_s:
                continue
            worker, index, _ = running.pop(head)
            self._workers.discard(worker)  # ray.kill: the process ends, sleeping or not
            again = [running.pop(ref)[1] for ref in list(queue)[1:] if ref in running]
            del queues[actor]
            waiting.extendleft(reversed([(k, specs[k]) for k in again]))
            yield index, timed_out(self.episode_timeout_s, now - since)

    def _fetch(self, ref: Any, wall_time_s: float) -> Any:
        """The episode's outcome; WorkerLost if its worker died or is stale; else TaskLost."""
        from ray import exceptions as rex
        try:
            outcome = self._ray.get(ref)
        except (rex.RayActorError, rex.NodeDiedError, rex.LocalRayletDiedError,
                rex.ObjectLostError) as exc:  # the process or the node went away
            return WorkerLost(wall_time_s, node_lost=not isinstance(exc, rex.RayActorError))
        except rex.OutOfMemoryError:
            why = "Ray's memory monitor killed the episode's worker"
        except rex.TaskCancelledError:
            why = "the episode's Ray task was cancelled"
        except rex.RayTaskError as exc:  # raised outside the episode: on the worker's side
            cause = getattr(exc, "cause", None) or exc
            detail = traceback.format_exception_only(type(cause), cause)[-1].strip()
            why = f"the Ray task failed on the worker: {detail}{import_hint(cause)}"
        except rex.RayError as exc:  # RuntimeEnvSetupError, ...: its first and last lines
            why = f"Ray could not run the episode: {type(exc).__name__}: {two_lines(exc)}"
        else:
            if isinstance(outcome, str) and outcome == STALE:
                return WorkerLost(wall_time_s, code_changed=True)
            return outcome
        return TaskLost(" ".join(why.split()), wall_time_s)
