"""The Ray processes of this test session: found, waited for, checked (every Ray test's end).

A test that starts Ray work - an actor, a task, a Ray instance of its own (`evaluate.py --ray`,
`ray start`) - must end with none of its processes left: one still running prints into a later
test's output (a Tune trial worker ended by SIGTERM prints "Exception ignored ... SystemExit:
1" from Ray's sigterm_handler when it goes) and holds CPUs the next test needs. Every process
of the session carries its id in AMR_TEST_RAY_SESSIONS (conftest.py: mark_session; a pytest
run started by a test adds its own id to the inherited ones), so its Ray processes are told
from other users' and other sessions' by their environment (/proc, Linux).

The session's loopback cluster (tests/ray_cluster.py) stays for the whole session: its node
processes (servers, agents) and its idle pool workers ("ray::IDLE", which run nothing of any
test) are not a test's; every other Ray worker process ("ray::EpisodeWorker", a Tune trial's,
a task's) and every process of another Ray instance is.
"""
from __future__ import annotations

import os
import signal
import time
import uuid
from pathlib import Path

SESSIONS_VARIABLE = "AMR_TEST_RAY_SESSIONS"
_session_id = ""


def mark_session() -> str:
    """Give this process (and what it starts) a session id of its own; the id."""
    global _session_id
    _session_id = uuid.uuid4().hex[:12]
    inherited = os.environ.get(SESSIONS_VARIABLE, "")
    os.environ[SESSIONS_VARIABLE] = f"{inherited}:{_session_id}" if inherited else _session_id
    return _session_id


def _read(path: str) -> bytes:
    with open(path, "rb") as stream:
        return stream.read()


def session_ray_processes() -> dict[int, tuple[int, str]]:
    """{pid: (parent pid, command line)} of the live Ray processes of this session."""
    found = {}
    for entry in os.scandir("/proc"):
        if not entry.name.isdigit() or int(entry.name) == os.getpid():
            continue
        try:
            argv = [a for a in _read(f"/proc/{entry.name}/cmdline").split(b"\0") if a]
            environ = _read(f"/proc/{entry.name}/environ").split(b"\0")
            stat = _read(f"/proc/{entry.name}/stat").decode(errors="replace")
        except OSError:  # gone meanwhile, or not ours
            continue
        if not argv:  # a zombie: it runs nothing any more
            continue
        ours = any(line.startswith(SESSIONS_VARIABLE.encode() + b"=") and _session_id.encode()
                   in line.split(b"=", 1)[1].split(b":") for line in environ)
        command = " ".join(a.decode(errors="replace") for a in argv).strip()
        if ours and _is_ray(command):
            parent = int(stat.rsplit(")", 1)[1].split()[1])
            found[int(entry.name)] = (parent, command)
    return found


def _is_ray(command: str) -> bool:
    """A Ray process: a worker (its title "ray::..."), a node's server or helper, the CLI."""
    first = command.split()[0] if command else ""
    return command.startswith("ray::") or f"{os.sep}ray{os.sep}" in command \
        or Path(first).name in ("ray", "raylet", "gcs_server")


def leftovers() -> dict[int, str]:
    """{pid: command} of the session's Ray processes that belong to no one now.

    All but the session cluster's node processes and idle pool workers: those descend from
    this process (the cluster's nodes are its children).
    """
    processes = session_ray_processes()

    def under_this_process(pid: int) -> bool:
        seen = set()
        while pid in processes and pid not in seen:
            seen.add(pid)
            pid = processes[pid][0]
        return pid == os.getpid()

    return {pid: command for pid, (_, command) in processes.items()
            if not (under_this_process(pid) and _of_the_node(command))}


# A node's own processes and pool workers that run nothing (Ray's process titles): the agents
# of each node, idle workers, object spilling and restoring workers.
_NODE_TITLES = ("ray::DashboardAgent", "ray::RuntimeEnvAgent", "ray::IDLE", "ray::SPILL_",
                "ray::RESTORE_", "ray::DELETE_")


def _of_the_node(command: str) -> bool:
    return not command.startswith("ray::") or command.startswith(_NODE_TITLES)


def wait_until_ended(timeout_s: float = 30.0) -> dict[int, str]:
    """Wait until no leftover Ray process runs; those still running after `timeout_s`.

    Those are then SIGKILLed (by their pid: processes this session started), so the tests
    after the one that left them start clean; the caller fails that test.
    """
    deadline = time.monotonic() + timeout_s
    while (left := leftovers()) and time.monotonic() < deadline:
        time.sleep(0.1)
    for pid in left:
        try:
            os.kill(pid, signal.SIGKILL)
        except OSError:
            pass
    return left
