"""evaluate.py --ray: episodes as Ray tasks give the local pool's results, and survive losses.

On the `ray_cluster` fixture (tests/ray_cluster.py): a head without CPUs and one worker node on
127.0.0.1, started from this venv (the shared-venv set-up of docs/tune.md "Sweep on a cluster"),
this process the driver. Every metric of every episode is compared with the local process pool's
run of the same episodes; a worker process killed mid-episode is retried, a second death and a lost
node are survived, and a cluster without CPUs ends the sweep with errors, not a hang.
"""
from __future__ import annotations

import csv
import dataclasses
import json
import os
import re
import shutil
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import pytest

from amr_evaluation.evaluation import EpisodeSpec, expand_grid, run_episodes
from amr_evaluation.evaluation_report import outcome_row
from amr_evaluation.executors import LocalPoolExecutor
from amr_evaluation.ray_executor import RayExecutor
from amr_evaluation.ray_workers import release_idle_warm_workers, warm_workers
from tests.ray_cluster import RAY_AUTH_VARIABLES

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO / "scripts"))
import evaluate  # noqa: E402
import evaluate_executors  # noqa: E402


class SlowStanding:
    """Commands zero, 3 ms of wall time per step.

    Announces itself in `folder` on its first step, so a test knows which episodes are running.
    """

    def __init__(self, dt, folder=""):
        self.folder, self.calls = folder, 0

    def compute_commands(self, z_scan, z_v, z_w):
        self.calls += 1
        if self.calls == 1 and self.folder:
            Path(self.folder, f"{os.getpid()}-{time.monotonic_ns()}").touch()
        time.sleep(0.003)
        return 0.0, 0.0


TIMINGS = ("wall_time_s", "filter_wall_time_s", "real_time_factor", "plan_time_ms")  # host speed


def _without_timings(result) -> dict:
    return {k: v for k, v in dataclasses.asdict(result).items() if k not in TIMINGS}


def _without_wall_time(outcome) -> dict:
    result = _without_timings(outcome.result) if outcome.result is not None else None
    row = outcome_row(outcome)
    row.pop("wall_time_s")
    return {"spec": outcome.spec, "error": outcome.error, "result": result, "row": row}


def _wait_for_files(folder: Path, count: int, timeout: float = 30.0) -> None:
    deadline = time.monotonic() + timeout
    while len(list(folder.iterdir())) < count:
        assert time.monotonic() < deadline, f"fewer than {count} episodes started"
        time.sleep(0.05)


def test_a_sweep_on_the_cluster_gives_the_local_pools_results(ray_cluster):
    specs = expand_grid("lab02,maze_deadends", "all", "ideal,turtlebot3", "0,1", duration=20.0)
    assert len(specs) == 20
    seen = {"local": [], "ray": []}
    local = run_episodes(specs, executor=LocalPoolExecutor(2),
                         progress=lambda done, total, o: seen["local"].append((done, total)))
    executor = RayExecutor(ray_cluster.address)
    remote = run_episodes(specs, executor=executor,
                          progress=lambda done, total, o: seen["ray"].append((done, total)))
    assert seen["ray"] == seen["local"] == [(k, 20) for k in range(1, 21)]
    assert all(o.error is None for o in remote)
    assert [_without_wall_time(o) for o in remote] == [_without_wall_time(o) for o in local]
    assert executor.describe() == f"the Ray cluster at {ray_cluster.address}: 2 CPUs on 2 node(s)"
    # Summaries only: the same metrics, no per-step trajectory to send back.
    summaries = run_episodes(specs[:4], executor=executor, trajectory=False)
    for full, summary in zip(remote, summaries):
        assert summary.result.trajectory == [] and len(full.result.trajectory) == 401
        assert outcome_row(summary) | {"wall_time_s": 0} == outcome_row(full) | {"wall_time_s": 0}


def test_navigation_and_localization_episodes_run_on_the_cluster_alike(ray_cluster):
    from amr_evaluation.localization_evaluation import LocalizationSpec, run_localization_specs
    executor = RayExecutor(ray_cluster.address)
    navigation = expand_grid("lab02", "outer", "ideal", "0", duration=20.0, goals="all",
                             pose_source="truth")
    local = run_episodes(navigation, executor=LocalPoolExecutor(2))
    remote = run_episodes(navigation, executor=executor)
    assert len(remote) == 3 and all(o.error is None for o in remote)
    assert [_without_wall_time(o) for o in remote] == [_without_wall_time(o) for o in local]
    localization = [LocalizationSpec("twin_maze_small", None, profile, 1, duration=10.0)
                    for profile in ("ideal", "turtlebot3")]
    local = run_localization_specs(localization, jobs=2)
    remote = run_localization_specs(localization, executor=executor)
    assert all(o.error is None for o in remote)
    assert [_without_timings(o.result) for o in remote] == \
        [_without_timings(o.result) for o in local]


def _table(stdout: str) -> list[str]:
    lines = stdout[stdout.index("world "):stdout.index("verdict:")].splitlines()
    return [re.sub(r"\s+\S+$", "", line) for line in lines]  # without the wall time column


def test_evaluate_py_on_ray_writes_the_local_pools_files(ray_cluster, tmp_path, capsys):
    args = ["--worlds", "lab02,wide_maze", "--profiles", "ideal,turtlebot3", "--seeds", "3",
            "--duration", "15"]
    assert evaluate.main([*args, "--jobs", "2", "--out", str(tmp_path / "pool")]) == 0
    pool_stdout = capsys.readouterr().out
    # Other driver processes, started elsewhere: the workers import the project from the venv.
    # One joins the cluster (its CPUs: --jobs is refused there), one starts (and stops) a Ray
    # instance of its own with --jobs CPUs.
    runs = {"cluster": ["--ray", ray_cluster.address], "local": ["--ray", "--jobs", "2"]}
    for name, ray_args in runs.items():
        proc = subprocess.run([sys.executable, str(REPO / "scripts" / "evaluate.py"), *args,
                               *ray_args, "--out", str(tmp_path / name)],
                              cwd=tmp_path, capture_output=True, text=True, timeout=180)
        assert proc.returncode == 0, proc.stderr
        where = f"the Ray cluster at {ray_cluster.address}: 2 CPUs on 2 node(s)" \
            if name == "cluster" else "a local Ray instance: 2 CPUs on 1 node(s)"
        assert f"on {where}, controller" in proc.stdout
        assert _table(proc.stdout) == _table(pool_stdout)
        assert proc.stdout.splitlines()[-2] == pool_stdout.splitlines()[-2]  # the verdict

    def episodes(name):
        data = json.loads((tmp_path / name / "results.json").read_text())
        return [{k: v for k, v in e.items() if k != "wall_time_s"} for e in data["episodes"]]

    def csv_rows(name):
        with open(tmp_path / name / "results.csv", newline="") as stream:
            return [{k: v for k, v in r.items() if k != "wall_time_s"}
                    for r in csv.DictReader(stream)]

    for name in runs:
        assert len(episodes(name)) == 10 and episodes(name) == episodes("pool")
        assert csv_rows(name) == csv_rows("pool")
        assert (tmp_path / name / "sheet.png").read_bytes() == \
            (tmp_path / "pool" / "sheet.png").read_bytes()


def test_a_driver_on_a_loopback_cluster_takes_the_loopback_address(tmp_path, monkeypatch):
    from amr_evaluation.ray_executor import _on_loopback
    assert _on_loopback("127.0.0.1:6379") and _on_loopback("localhost:1234")
    assert not _on_loopback("10.1.2.3:6379") and not _on_loopback("head.lab:6379")
    monkeypatch.setenv("RAY_TMPDIR", str(tmp_path))
    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    assert not _on_loopback("auto")  # no running cluster noted
    (tmp_path / "ray").mkdir()
    (tmp_path / "ray" / "ray_current_cluster").write_text("127.0.0.1:6379\n")
    assert _on_loopback("auto")
    monkeypatch.setenv("RAY_ADDRESS", "10.1.2.3:6379")
    assert not _on_loopback("auto")


def test_a_worker_killed_mid_episode_is_retried_and_a_second_death_reported(ray_cluster,
                                                                          tmp_path):
    marker = tmp_path / "killed-once"
    specs = [EpisodeSpec("lab02", "outer", duration=2.0, controller="tests.controllers:"
                         "KillsItsProcessOnce", params={"marker": str(marker)}),
             EpisodeSpec("lab02", "inner", duration=2.0,
                         controller="tests.test_evaluation:ExitsTheProcess"),
             EpisodeSpec("lab02", "outer", duration=2.0,
                         controller="tests.test_evaluation:Standing")]
    seen = []
    outcomes = run_episodes(specs, executor=RayExecutor(ray_cluster.address),
                            progress=lambda done, total, o: seen.append(done))
    assert seen == [1, 2, 3]
    killed, exits, standing = outcomes
    assert marker.exists()  # its first run died with its process; the retry ran it
    assert killed.error is None and killed.result.steps == 40
    assert killed.result.distance_m == standing.result.distance_m == 0.0
    assert exits.result is None
    assert "Ray worker process died during this episode (tried 2 times)" in exits.error
    # The local pool does not retry: the same killed episode is its error there.
    marker.unlink()
    (local,) = run_episodes(specs[:1], executor=LocalPoolExecutor(2))
    assert "worker process died (killed by signal 9)" in local.error


def test_an_episode_past_its_time_limit_ends_its_ray_worker_and_the_others_still_run(
        ray_cluster):
    """A controller sleeping forever used to hang the sweep on Ray too."""
    hows = ["none", "sleep", "none", "none", "sleep", "none"]
    specs = [EpisodeSpec("lab02", "outer", seed=k, duration=1.0,
                         controller="tests.controllers:Misbehaves", params={"how": how})
             for k, how in enumerate(hows)]
    executor = evaluate_executors.ray_executor(ray_cluster.address, None, None, 0.0, 3.0)
    try:
        assert executor.episode_timeout_s == 3.0
        seen = []
        outcomes = run_episodes(specs, executor=executor,
                                progress=lambda done, total, o: seen.append(done))
        # The workers that slept were killed and replaced: the executor runs on.
        (after,) = run_episodes(specs[:1], executor=executor)
    finally:
        executor.close()
    assert seen == [1, 2, 3, 4, 5, 6]
    for how, outcome in zip(hows, outcomes):
        if how == "sleep":
            assert outcome.result is None
            assert "ran past its wall-clock limit of 3 s" in outcome.error, outcome.error
            assert 3.0 <= outcome.wall_time_s < 60.0
        else:
            assert outcome.error is None and outcome.result.steps == 20, outcome.error
    assert after.error is None


def test_a_worker_node_lost_mid_sweep_is_survived(ray_cluster, tmp_path):
    ray = ray_cluster.ray
    release_idle_warm_workers(ray)
    extra = ray_cluster.add_worker(1)
    executor = RayExecutor(ray_cluster.address)
    assert executor.cluster_cpus() == 3
    # A first run leaves a warm worker on each of the three CPUs, the new node's too, so the
    # sweep below starts its first three episodes at once, one on the node that is lost.
    run_episodes([EpisodeSpec("lab02", "outer", seed=k, duration=0.5) for k in range(3)],
                 executor=RayExecutor(ray_cluster.address))
    ray.get([worker.ready.remote() for worker in warm_workers(ray).values()], timeout=60)
    assert len(warm_workers(ray)) == 3
    started = tmp_path / "started"
    started.mkdir()
    specs = [EpisodeSpec("lab02", start, seed=seed, duration=30.0,
                         controller=f"{__name__}:SlowStanding", params={"folder": str(started)})
             for start in ("outer", "inner") for seed in range(2)]
    killer = threading.Thread(target=lambda: (_wait_for_files(started, 3),
                                              ray_cluster.kill_worker(extra)))
    killer.start()
    begin = time.monotonic()
    outcomes = run_episodes(specs, executor=executor, )
    killer.join()
    assert [o.error for o in outcomes] == [None] * 4
    assert all(o.result.steps == 600 for o in outcomes)
    assert len(list(started.iterdir())) >= 5  # one episode started twice: retried elsewhere
    assert time.monotonic() - begin < 60
    assert executor.cluster_cpus() == 2


def test_a_cluster_without_cpus_ends_the_sweep_with_errors_not_a_hang(ray_cluster, tmp_path):
    started = tmp_path / "started"
    started.mkdir()
    # Long enough (2,400 steps of 3 ms) that the node is lost mid-episode on a loaded machine.
    specs = [EpisodeSpec("lab02", "outer", seed=seed, duration=120.0,
                         controller=f"{__name__}:SlowStanding", params={"folder": str(started)})
             for seed in range(3)]
    (node,) = ray_cluster.workers
    killer = threading.Thread(target=lambda: (_wait_for_files(started, 2),
                                              ray_cluster.kill_worker(node)))
    killer.start()
    try:
        begin = time.monotonic()
        outcomes = run_episodes(specs, executor=RayExecutor(ray_cluster.address,
                                                            no_worker_timeout_s=3.0))
        killer.join()
        elapsed = time.monotonic() - begin
    finally:
        ray_cluster.workers.append(ray_cluster.add_worker(2))  # for the tests after this one
    assert all(o.result is None and "no Ray node with a CPU was alive for 3 s" in o.error
               for o in outcomes), [o.error for o in outcomes]
    assert elapsed < 30


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def test_the_manuals_ray_start_recipe_works_from_an_empty_home(tmp_path, ray_processes_end):
    """docs/tune.md "Sweep on a cluster" here: a token, `ray start --head`, `--ray auto`.

    As a newcomer: HOME empty, no Ray variables. A Ray temporary folder of its own, so `auto`
    finds this head, not another Ray on the machine (short: Ray's socket paths are limited).
    """
    home = tmp_path / "home"
    home.mkdir()
    ray_tmp = Path(tempfile.mkdtemp(prefix="amr-ray-"))
    env = {k: v for k, v in os.environ.items() if k not in RAY_AUTH_VARIABLES}
    env.update(HOME=str(home), RAY_TMPDIR=str(ray_tmp), RAY_USAGE_STATS_ENABLED="0")
    ray_cli = str(Path(sys.executable).parent / "ray")
    made = subprocess.run([ray_cli, "get-auth-token", "--generate"], env=env,
                          capture_output=True, text=True, timeout=60)
    assert made.returncode == 0, made.stderr
    port = _free_port()
    head_log = tmp_path / "head.log"
    with open(head_log, "w") as log:
        head = subprocess.Popen(
            [ray_cli, "start", "--head", "--port", str(port), "--num-cpus", "1",
             "--include-dashboard", "false", "--block"],
            env={**env, "RAY_AUTH_MODE": "token", "RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER": "0"},
            stdout=log, stderr=subprocess.STDOUT)
    try:
        deadline = time.monotonic() + 120
        while "Ray runtime started" not in head_log.read_text():
            assert head.poll() is None and time.monotonic() < deadline, head_log.read_text()
            time.sleep(0.2)
        evaluate_py = [sys.executable, str(REPO / "scripts" / "evaluate.py"), "--ray", "auto",
                       "--ray-keep-workers", "0", "--worlds", "lab02", "--starts", "outer",
                       "--duration", "1", "--no-sheet"]
        proc = subprocess.run([*evaluate_py, "--out", str(tmp_path / "out")], cwd=tmp_path,
                              env=env, capture_output=True, text=True, timeout=180)
        # The head requires the token: a driver without one (another empty HOME) is refused
        # (after Ray's connection retries, 2 here instead of 20).
        stranger = tmp_path / "stranger"
        stranger.mkdir()
        refused = subprocess.run(
            [*evaluate_py, "--out", str(tmp_path / "refused")], cwd=tmp_path,
            env={**env, "HOME": str(stranger), "RAY_gcs_server_port_wait_time_s": "2"},
            capture_output=True, text=True, timeout=180)
    finally:
        head.terminate()  # as Ctrl-C: `ray start --block` stops the node's processes
        head.wait(timeout=60)
        shutil.rmtree(ray_tmp, ignore_errors=True)
    assert proc.returncode == 0, proc.stderr
    assert f"on the Ray cluster at 127.0.0.1:{port}: 1 CPUs on 1 node(s)" in proc.stdout
    assert refused.returncode == 2, refused.stdout + refused.stderr
    assert "a cluster with token authentication needs" in refused.stderr.splitlines()[-1]
    assert sorted(p.name for p in home.iterdir()) == [".ray"]  # the token, as the manual says
    assert len((home / ".ray" / "auth_token").read_text()) == 64
