"""Warm Ray workers: the next run finds them ready, never running code older than the files.

On the `ray_cluster` fixture (tests/ray_cluster.py, a worker node of 2 CPUs), this process the
driver. A run joining a cluster leaves its EpisodeWorkers for the next run; they end when idle
for `keep_workers_s` and free their CPUs; a module they imported that changed on disk makes
them answer STALE and the driver replaces them; `keep_workers_s=0` leaves nothing behind.
"""
from __future__ import annotations

import importlib
import os
import sys
import time
from pathlib import Path

import pytest

import tests.controllers
from amr_evaluation.evaluation import EpisodeSpec, run_episodes
from amr_evaluation.ray_executor import RayExecutor
from amr_evaluation.ray_workers import ModuleWatch, release_idle_warm_workers, warm_workers

REPO = Path(__file__).resolve().parent.parent


def _specs(folder: Path, count: int = 4) -> list[EpisodeSpec]:
    return [EpisodeSpec("lab02", "outer", seed=k, duration=1.0,
                        controller="tests.controllers:NotesItsProcess",
                        params={"folder": str(folder)}) for k in range(count)]


def _pids(folder: Path) -> set[str]:
    """The processes that ran episodes since the last call (their notes are removed)."""
    pids = set()
    for note in folder.iterdir():
        pids.add(note.name.split("-")[0])
        note.unlink()
    return pids


def _wait_until(condition, timeout: float = 30.0) -> bool:
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.2)
    return True


def test_a_module_changed_on_disk_is_seen_and_installed_ones_are_not_watched(tmp_path,
                                                                             monkeypatch):
    watch = ModuleWatch()
    module = tmp_path / "edited_controller.py"
    module.write_text("GAIN = 1.0\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    try:
        importlib.import_module("edited_controller")
        watch.note_new()
        assert watch.changed() == []
        stat = module.stat()
        os.utime(module, ns=(stat.st_atime_ns, stat.st_mtime_ns + 10**9))  # edited
        assert watch.changed() == [os.path.realpath(module)]
        module.unlink()  # a deleted file is a change too
        assert watch.changed() == [os.path.realpath(module)]
    finally:
        sys.modules.pop("edited_controller", None)
    watched = set(watch._stamps)
    assert os.path.realpath(REPO / "amr_evaluation" / "ray_workers.py") in watched
    assert not any("site-packages" in path for path in watched)  # numpy, Ray, ...: installed


@pytest.mark.slow
def test_the_next_run_finds_the_workers_warm_and_a_changed_module_replaces_them(ray_cluster,
                                                                             tmp_path):
    ray = ray_cluster.ray
    release_idle_warm_workers(ray)
    folder = tmp_path / "pids"
    folder.mkdir()
    first = run_episodes(_specs(folder), executor=RayExecutor(ray_cluster.address))
    assert [o.error for o in first] == [None] * 4
    started = _pids(folder)
    assert 1 <= len(started) <= 2 and len(warm_workers(ray)) == 2  # one per CPU, left warm

    second = run_episodes(_specs(folder), executor=RayExecutor(ray_cluster.address))
    assert [(o.error, o.result.steps, o.result.distance_m) for o in second] == \
        [(o.error, o.result.steps, o.result.distance_m) for o in first]
    assert _pids(folder) <= started  # the same processes: nothing started again

    # The controller's file changes under the warm workers: they must not run the old code.
    source = Path(tests.controllers.__file__)
    stat = source.stat()
    try:
        os.utime(source, ns=(stat.st_atime_ns, stat.st_mtime_ns + 10**9))
        third = run_episodes(_specs(folder), executor=RayExecutor(ray_cluster.address))
    finally:
        os.utime(source, ns=(stat.st_atime_ns, stat.st_mtime_ns))
    assert [o.error for o in third] == [None] * 4
    assert not _pids(folder) & started  # fresh processes ran every episode


@pytest.mark.slow
def test_idle_warm_workers_end_and_free_their_cpus(ray_cluster, tmp_path):
    ray = ray_cluster.ray
    release_idle_warm_workers(ray)
    (tmp_path / "pids").mkdir()
    outcomes = run_episodes(_specs(tmp_path / "pids", 2),
                            executor=RayExecutor(ray_cluster.address, keep_workers_s=1.0))
    assert [o.error for o in outcomes] == [None] * 2
    assert warm_workers(ray)
    assert _wait_until(lambda: not warm_workers(ray))  # about 1-2 s after the run
    assert _wait_until(lambda: ray.available_resources().get("CPU", 0) == 2)


@pytest.mark.slow
def test_keep_workers_zero_leaves_nothing_behind_and_frees_idle_warm_ones(ray_cluster,
                                                                          tmp_path):
    ray = ray_cluster.ray
    (tmp_path / "pids").mkdir()
    run_episodes(_specs(tmp_path / "pids", 2), executor=RayExecutor(ray_cluster.address))
    assert warm_workers(ray)  # left by a run with the default 60 s
    with RayExecutor(ray_cluster.address, keep_workers_s=0) as executor:
        outcomes = run_episodes(_specs(tmp_path / "pids", 2), executor=executor)
        assert not warm_workers(ray)  # the idle warm ones were ended for this run's CPUs
    assert [o.error for o in outcomes] == [None] * 2
    assert _wait_until(lambda: ray.available_resources().get("CPU", 0) == 2)


@pytest.mark.parametrize("value", [-1.0, float("nan"), float("inf")])
def test_an_absurd_keep_time_is_refused(value):
    with pytest.raises(ValueError, match="keep_workers_s"):
        RayExecutor("127.0.0.1:6379", keep_workers_s=value)
