"""The Ray actors that run episodes for RayExecutor, and the warm ones that outlive a run.

A Ray worker process belongs to one job (one evaluate.py run): every run would start its own
processes, which import Ray, the simulator and its compiled kernels (1.5-2.5 s on 2 cores,
most of what a short sweep on Ray costs beyond the local pool). An EpisodeWorker is a Ray
actor that runs one episode after another. Joining a running cluster, RayExecutor makes them
*warm*: detached, named by `worker_key()` (same Python, project checkout, script folder,
working directory and runtime_env, hence the same code), so the next run on that cluster finds
them imported and ready. A warm worker

- holds its CPU while it lives and ends itself after `keep_s` seconds without an episode;
- never runs code older than the files: before each episode it compares the modification
  times of every module it imported from outside the Python installation (this project, the
  user's controllers) with those at import, and answers STALE instead of running if one
  changed; the driver then replaces it with a fresh process.
"""
from __future__ import annotations

import hashlib
import json
import os
import sys
import sysconfig
import threading
import time
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

from amr_evaluation.executors import _preload

NAMESPACE = "amr_evaluation"
WARM_PREFIX = "amr-episode-worker-"
STALE = "amr_evaluation.ray_workers.STALE"  # run()'s answer when its code changed on disk


def worker_key(runtime_env: Mapping[str, Any] | None) -> str:
    """Which warm workers this driver may use: those that import the same code alike.

    Ray puts the driver's script folder and working directory on a job's workers' sys.path,
    and a runtime_env may bring other code: all of it is in the key, with the interpreter and
    this project's folder.
    """
    script = os.path.dirname(os.path.abspath(sys.argv[0])) if sys.argv and sys.argv[0] else ""
    parts = [sys.executable, sys.version, str(Path(__file__).resolve().parent.parent), script,
             os.getcwd(), json.dumps(runtime_env or {}, sort_keys=True, default=str)]
    return hashlib.sha1("\0".join(parts).encode()).hexdigest()[:12]


def _installation_prefixes() -> tuple[str, ...]:
    """Folders whose modules never change under a running worker: the stdlib, site-packages."""
    paths = sysconfig.get_paths()
    found = {sys.prefix, sys.base_prefix, sys.exec_prefix, paths["stdlib"], paths["purelib"],
             paths["platlib"]}
    return tuple(os.path.join(os.path.realpath(p), "") for p in found if p)


class ModuleWatch:
    """Modification times of the modules a process imported from outside the installation."""

    def __init__(self) -> None:
        self._skip = _installation_prefixes()
        self._seen: set[str] = set()
        self._stamps: dict[str, int] = {}  # file -> st_mtime_ns when first seen
        self.note_new()

    def note_new(self) -> None:
        """Record the files of modules imported since the last call."""
        for name in set(sys.modules) - self._seen:
            self._seen.add(name)
            path = getattr(sys.modules.get(name), "__file__", None)
            if not path:
                continue
            path = os.path.realpath(path)
            if path.startswith(self._skip) or path in self._stamps:
                continue
            try:
                self._stamps[path] = os.stat(path).st_mtime_ns
            except OSError:
                continue

    def changed(self) -> list[str]:
        """Files changed (or gone) since their module was imported."""
        out = []
        for path, stamp in self._stamps.items():
            try:
                if os.stat(path).st_mtime_ns != stamp:
                    out.append(path)
            except OSError:
                out.append(path)
        return out


class EpisodeWorker:
    """A Ray actor (wrapped with ray.remote by RayExecutor) that runs episode tasks in turn.

    `keep_s` > 0: a warm worker, which ends its process after that long without an episode.
    """

    def __init__(self, preload: Sequence[str] = (), keep_s: float = 0.0) -> None:
        _preload(preload)
        self._watch = ModuleWatch()
        self._busy = False
        self._last = time.monotonic()
        if keep_s > 0:
            threading.Thread(target=self._end_when_idle, args=(float(keep_s),),
                             name="idle-end", daemon=True).start()

    def ready(self) -> tuple[int, str]:
        """(process id, Ray node id): the worker is up (its constructor ran)."""
        import ray
        return os.getpid(), ray.get_runtime_context().get_node_id()

    def run(self, task: Callable[[Any], Any], preload: Sequence[str], spec: Any) -> Any:
        """task(spec), or STALE when a module this process imported changed on disk."""
        self._busy = True
        try:
            if self._watch.changed():
                return STALE
            _preload(preload)
            return task(spec)
        finally:
            self._watch.note_new()
            self._last, self._busy = time.monotonic(), False

    def idle_s(self) -> float:
        """Seconds since the last episode ended; -1 while one runs (call in group 'control')."""
        return -1.0 if self._busy else time.monotonic() - self._last

    def _end_when_idle(self, keep_s: float) -> None:
        while True:
            time.sleep(min(keep_s, 5.0) / 2)
            if not self._busy and time.monotonic() - self._last > keep_s:
                import ray
                try:  # ends this actor for good (a detached actor outlives its job)
                    ray.kill(ray.get_runtime_context().current_actor, no_restart=True)
                finally:
                    time.sleep(10.0)
                    os._exit(0)  # ray.kill did not end the process


def warm_workers(ray: Any, key: str | None = None) -> dict[str, Any]:
    """The live warm workers on the cluster (of `key`, or all), by name."""
    prefix = WARM_PREFIX + (f"{key}-" if key else "")
    found = {}
    for entry in ray.util.list_named_actors(all_namespaces=True):
        name = entry["name"] if isinstance(entry, dict) else entry
        namespace = entry.get("namespace") if isinstance(entry, dict) else NAMESPACE
        if namespace != NAMESPACE or not name.startswith(prefix):
            continue
        try:
            found[name] = ray.get_actor(name, namespace=NAMESPACE)
        except ValueError:  # ended since the listing
            continue
    return found


def release_idle_warm_workers(ray: Any, keep_key: str | None = None,
                              timeout_s: float = 5.0) -> int:
    """End the idle warm workers (all, or all but `keep_key`'s) and wait until they are gone.

    Their CPUs are free when this returns (within `timeout_s` for the answers and again for
    the ends). Busy ones (another run's episode) are left to end by themselves. Returns how
    many ended.
    """
    named = {name: handle for name, handle in warm_workers(ray).items()
             if not keep_key or not name.startswith(f"{WARM_PREFIX}{keep_key}-")}
    if not named:
        return 0
    refs = {handle.idle_s.options(concurrency_group="control").remote(): name
            for name, handle in named.items()}
    ready, _ = ray.wait(list(refs), num_returns=len(refs), timeout=timeout_s)
    ended = set()
    for ref in ready:
        try:
            busy = ray.get(ref) < 0
        except Exception:  # noqa: BLE001 - gone already
            continue
        if not busy:
            ray.kill(named[refs[ref]], no_restart=True)
            ended.add(refs[ref])
    deadline = time.monotonic() + timeout_s  # ray.kill returns before the process ends
    while ended & set(warm_workers(ray)) and time.monotonic() < deadline:
        time.sleep(0.05)
    return len(ended)
