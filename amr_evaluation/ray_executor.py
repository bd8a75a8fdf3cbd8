"""Episodes as Ray tasks: on a local Ray instance started here, or on a running Ray cluster.

    with RayExecutor() as executor:              # a local instance on 127.0.0.1, stopped after
        outcomes = run_episodes(specs, executor=executor)
    with RayExecutor("auto") as executor:        # the cluster this machine belongs to
        ...

Needs the optional `cluster` extra (`pip install -e .[cluster]`, or requirements-cluster.lock);
nothing else in the project imports Ray. Every node's workers must import this project from the
same venv path (or a runtime_env that installs it): see README "Sweep on a cluster".

Each episode is one task of 1 CPU. A task whose worker process or node died is retried once
(Ray's max_retries); a second loss, or an error Ray raises for the task (its arguments could
not be unpickled on the worker, ...), becomes that episode's TaskLost with the reason. While no
node with a CPU is alive for `no_worker_timeout_s`, the episodes left are reported lost instead
of waiting forever. Exceptions inside an episode are its own error outcome already (run_one),
never retried: episodes are deterministic.
"""
from __future__ import annotations

import logging
import os
import time
import traceback
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping, Sequence

from amr_evaluation.executors import TaskLost

__all__ = ["RayExecutor", "RaySetupError", "LOCAL_RAY_ENV"]

# A Ray instance started here: usage statistics off, every Ray process bound to 127.0.0.1
# (with the loopback address as node IP, Ray's servers listen on it alone), token
# authentication as Ray's default for a new local instance but stated, so Ray does not warn.
# Read by Ray at import: set before the first `import ray` of the process (connect() does).
LOCAL_RAY_ENV = {"RAY_USAGE_STATS_ENABLED": "0", "RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER": "0",
                 "RAY_AUTH_MODE": "token"}
RETRIES = 1


class RaySetupError(RuntimeError):
    """Ray is missing or the cluster cannot be reached; the message says which and what to do."""


def _run_task(task: Callable[[Any], Any], preload: Sequence[str], spec: Any) -> Any:
    """What a Ray worker runs: the episode task (preloading its modules the first time)."""
    from amr_evaluation.executors import _preload
    _preload(preload)
    return task(spec)


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
    project in py_modules).
    """

    def __init__(self, address: str | None = None, num_cpus: int | None = None,
                 runtime_env: Mapping[str, Any] | None = None,
                 no_worker_timeout_s: float = 60.0) -> None:
        self.address = address or None
        self.num_cpus = num_cpus
        self.runtime_env = dict(runtime_env) if runtime_env else None
        self.no_worker_timeout_s = float(no_worker_timeout_s)
        self._ray: Any = None
        self._owned = False
        self._remote: Any = None

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
        self._remote = self._ray.remote(num_cpus=1, max_retries=RETRIES,
                                        retry_exceptions=False)(_run_task)

    def close(self) -> None:
        """Stop the local instance this executor started, or disconnect from the cluster."""
        if self._ray is not None and self._owned:
            self._ray.shutdown()
        self._ray, self._owned, self._remote = None, False, None

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
        """Episodes that can run at once: the cluster's CPUs (each task takes one)."""
        return max(1, min(self.cluster_cpus(), episodes))

    # --- running -------------------------------------------------------------------------

    def run(self, task: Callable[[Any], Any], specs: Sequence[Any],
            preload: Sequence[str] = ()) -> Iterator[tuple[int, Any]]:
        """Yield (index, outcome or TaskLost) as tasks finish.

        At most a window of a few tasks per CPU is submitted ahead, so one `ray.wait` stays
        cheap for sweeps of thousands and an interrupted sweep has little to cancel.
        """
        self.connect()
        ray = self._ray
        task_ref = ray.put(task)
        preload = tuple(preload)
        waiting = list(enumerate(specs))[::-1]  # popped from the end: spec order
        running: dict[Any, tuple[int, float]] = {}  # ref -> (index, submitted at)
        no_cpu_since: float | None = None
        window, window_checked = 16, 0.0
        try:
            while waiting or running:
                if time.monotonic() - window_checked > 2.0:  # nodes may come and go
                    window, window_checked = max(16, 4 * self.cluster_cpus()), time.monotonic()
                while waiting and len(running) < window:
                    index, spec = waiting.pop()
                    ref = self._remote.remote(task_ref, preload, spec)
                    running[ref] = (index, time.perf_counter())
                ready, _ = ray.wait(list(running), num_returns=1, timeout=1.0,
                                    fetch_local=False)
                if ready:  # and every other one finished by now
                    ready, _ = ray.wait(list(running), num_returns=len(running), timeout=0,
                                        fetch_local=False)
                for ref in ready:
                    index, submitted = running.pop(ref)
                    yield index, self._fetch(ref, time.perf_counter() - submitted)
                if ready or self.cluster_cpus() > 0:
                    no_cpu_since = None
                    continue
                no_cpu_since = no_cpu_since or time.monotonic()
                if time.monotonic() - no_cpu_since >= self.no_worker_timeout_s:
                    lost = (f"no Ray node with a CPU was alive for {self.no_worker_timeout_s:g} s "
                            "(the cluster lost its worker nodes): the episode did not run")
                    for ref, (index, submitted) in list(running.items()):
                        ray.cancel(ref, force=True)
                        yield index, TaskLost(lost, time.perf_counter() - submitted)
                    running.clear()
                    while waiting:
                        yield waiting.pop()[0], TaskLost(lost)
        finally:
            for ref in running:  # interrupted (Ctrl-C, an exception in the consumer)
                try:
                    ray.cancel(ref, force=True)
                except Exception:  # noqa: BLE001 - best effort while leaving
                    pass

    def _fetch(self, ref: Any, wall_time_s: float) -> Any:
        """The task's outcome, or TaskLost saying what Ray reported."""
        from ray import exceptions as rex
        try:
            return self._ray.get(ref)
        except rex.WorkerCrashedError:
            why = ("the Ray worker process died during this episode (tried "
                   f"{RETRIES + 1} times): the controller or the simulator ended the process "
                   "(os._exit, a crash, out of memory)")
        except rex.OutOfMemoryError:
            why = f"Ray's memory monitor killed the episode's worker (tried {RETRIES + 1} times)"
        except (rex.NodeDiedError, rex.LocalRayletDiedError, rex.ObjectLostError) as exc:
            why = (f"the Ray node running this episode was lost (tried {RETRIES + 1} times): "
                   f"{type(exc).__name__}")
        except rex.TaskCancelledError:
            why = "the episode's Ray task was cancelled"
        except rex.RayTaskError as exc:  # raised outside the episode: on the worker's side
            cause = getattr(exc, "cause", None) or exc
            detail = traceback.format_exception_only(type(cause), cause)[-1].strip()
            hint = (" (do the cluster's workers import this project? see README 'Sweep on a "
                    "cluster')") if isinstance(cause, ImportError) else ""
            why = f"the Ray task failed on the worker: {detail}{hint}"
        except rex.RayError as exc:  # RuntimeEnvSetupError, ...: its first and last lines
            lines = [line.strip() for line in str(exc).splitlines() if line.strip()] or [""]
            detail = lines[0] if len(lines) == 1 else f"{lines[0]} ... {lines[-1]}"
            why = f"Ray could not run the episode: {type(exc).__name__}: {detail[:400]}"
        return TaskLost(" ".join(why.split()), wall_time_s)
