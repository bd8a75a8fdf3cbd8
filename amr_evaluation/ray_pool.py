"""The Ray workers of one run of RayExecutor: ready, starting, and the node each one runs on.

WorkerSet creates EpisodeWorker actors up to the cluster's CPUs (warm ones of an earlier run
joined first), notes which node each runs on, and ends them; WorkerLost is the outcome of an
episode whose worker process or node went away.
"""
from __future__ import annotations

import time
import uuid
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from amr_evaluation.ray_workers import NAMESPACE, WARM_PREFIX, warm_workers, worker_key

if TYPE_CHECKING:
    from amr_evaluation.ray_executor import RayExecutor


def import_hint(cause: BaseException | str) -> str:
    """A hint when the workers cannot import this project."""
    text = cause if isinstance(cause, str) else type(cause).__name__
    return (" (do the cluster's workers import this project? see docs/tune.md, 'Sweep "
            "on a cluster')") if ("ImportError" in text or "ModuleNotFoundError" in text) else ""


def two_lines(exc: BaseException) -> str:
    """The first and last non-empty lines of a (long) Ray error message."""
    lines = [line.strip() for line in str(exc).splitlines() if line.strip()] or [""]
    detail = lines[0] if len(lines) == 1 else f"{lines[0]} ... {lines[-1]}"
    return detail[:400]


@dataclass(frozen=True)
class WorkerLost:
    """An episode that did not finish because its worker ended (or found its code changed)."""

    wall_time_s: float
    node_lost: bool = False
    code_changed: bool = False

    def why(self, pool: "WorkerSet", worker: Any, tries: int) -> str:
        """The episode's error after its last try."""
        if self.node_lost or not pool.node_alive(worker):
            return f"the Ray node running this episode was lost (tried {tries} times)"
        return (f"the Ray worker process died during this episode (tried {tries} times): the "
                "controller or the simulator ended the process (os._exit, a crash, out of "
                "memory)")


class WorkerSet:
    """The EpisodeWorkers of one run: ready, starting, and the node each one runs on."""

    def __init__(self, executor: "RayExecutor") -> None:
        self.ray, self.preload = executor._ray, ()
        self._executor = executor
        self._class = executor._worker_class
        self._keep_s = executor.keep_workers_s
        self._key = worker_key(executor.runtime_env)
        self.ready: list[Any] = []  # started, alive
        self.starting: dict[Any, Any] = {}  # ready() ref -> worker
        # actor id -> node id, kept after a worker is discarded (its loss message asks)
        self._node: dict[Any, str | None] = {}
        self._handles: dict[Any, Any] = {}  # actor id -> worker: the members
        self._failed_in_a_row = 0  # worker creations
        self.failure: str | None = None  # why no worker can be created
        self._checked, self._cpus = 0.0, 0
        if self._keep_s:
            for worker in warm_workers(self.ray, self._key).values():
                self._join(worker)

    def new_run(self, preload: tuple[str, ...]) -> None:
        """A run begins: its modules to preload; creation failures of earlier runs forgotten."""
        self.preload, self.failure, self._failed_in_a_row = preload, None, 0

    def _join(self, worker: Any) -> None:
        self._handles[worker._actor_id] = worker
        self._node[worker._actor_id] = None
        self.starting[worker.ready.remote()] = worker

    def top_up(self, episodes_left: int) -> None:
        """Create workers up to the cluster's CPUs (at most one per episode left)."""
        if self.failure:
            return
        if time.monotonic() - self._checked > 2.0:  # nodes may come and go
            self._cpus, self._checked = self._executor.cluster_cpus(), time.monotonic()
        while len(self._handles) < min(self._cpus, episodes_left):
            if self._keep_s:
                worker = self._class.options(
                    name=f"{WARM_PREFIX}{self._key}-{uuid.uuid4().hex[:8]}", namespace=NAMESPACE,
                    lifetime="detached").remote(self.preload, self._keep_s)
            else:
                worker = self._class.remote(self.preload)
            self._join(worker)

    def started(self, ref: Any) -> None:
        """A worker answered ready(): ready now; or its creation failed (noted in `failure`)."""
        worker = self.starting.pop(ref)
        try:
            _, node = self.ray.get(ref)
        except Exception as exc:  # noqa: BLE001 - creation failed (import, runtime_env, ...)
            self._forget(worker)
            self._failed_in_a_row += 1
            if self._failed_in_a_row >= 3:
                text = two_lines(exc)
                self.failure = " ".join(
                    f"the Ray workers cannot start an episode worker: {text}"
                    f"{import_hint(text)}".split())
            return
        self._failed_in_a_row = 0
        self._node[worker._actor_id] = node
        self.ready.append(worker)

    def node_alive(self, worker: Any) -> bool:
        """Whether the node the worker ran on is alive (True if unknown)."""
        node = self._node.get(worker._actor_id)
        if node is None:
            return True
        return any(n.get("NodeID") == node and n.get("Alive") for n in self.ray.nodes())

    def discard(self, worker: Any) -> None:
        """A worker that died or is stale: ended for good, no longer a member."""
        try:
            self.ray.kill(worker, no_restart=True)
        except Exception:  # noqa: BLE001 - already gone
            pass
        if worker in self.ready:
            self.ready.remove(worker)
        self._forget(worker)

    def _forget(self, worker: Any) -> None:
        self._handles.pop(worker._actor_id, None)

    def leave(self) -> None:
        """Warm workers stay (they end when idle), others are ended now."""
        if self._keep_s:
            return
        for worker in list(self._handles.values()):
            try:
                self.ray.kill(worker, no_restart=True)
            except Exception:  # noqa: BLE001 - already gone
                pass
        self._handles.clear()
