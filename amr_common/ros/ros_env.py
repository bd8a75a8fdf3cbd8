"""Isolation of local ROS 2 graphs: a private ROS_DOMAIN_ID and loopback-only discovery.

Tests, CI and local simulations must not talk to the LAN nor to each other. A domain id is
claimed with an exclusive file lock held for the life of the process, so concurrent test runs,
xdist workers and simulations on one machine never share a domain. The lock file names its
holder (program and pid): a domain chosen by the user is registered the same way when free, so
`local_graphs("run_sim")` finds the local simulators (teleop.py drives the one running). The
locks live in <tmp>/amr-ros-domains ($AMR_DOMAIN_LOCK_DIR if set). No rclpy import here: this
must run before rclpy initialises (the RMW reads the environment at init).
"""
from __future__ import annotations

import fcntl
import json
import os
import sys
import tempfile
from pathlib import Path

# Domain ids usable without port clashes on Linux are 0-101 (0 is everyone's default).
FIRST_DOMAIN_ID = 1
LAST_DOMAIN_ID = 101
# The largest id DDS accepts: higher ones give ports above 65535 (Fast DDS fails at startup).
MAX_DOMAIN_ID = 232
_held_locks: list = []  # open lock files: closing one releases its domain


def _lock_dir() -> Path:
    return Path(os.environ.get("AMR_DOMAIN_LOCK_DIR") or
                Path(tempfile.gettempdir()) / "amr-ros-domains")


def _lock(domain_id: int, program: str) -> bool:
    """Hold domain_id's lock for the life of the process, naming `program`; False if held."""
    folder = _lock_dir()
    folder.mkdir(parents=True, exist_ok=True)
    # "a+": opening must not empty a file another process holds (its name in it).
    lock_file = open(folder / f"domain-{domain_id}.lock", "a+")
    try:
        fcntl.flock(lock_file, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        lock_file.close()
        return False
    lock_file.truncate(0)
    lock_file.write(json.dumps({"program": program, "pid": os.getpid()}))
    lock_file.flush()
    _held_locks.append(lock_file)
    return True


def _this_program() -> str:
    script = Path(sys.argv[0]) if sys.argv and sys.argv[0] else Path("python")
    return script.parent.name if script.stem == "__main__" else script.stem  # python -m x: x


def claim_free_domain_id(preferred: int | None = None, program: str | None = None) -> int:
    """Return a domain id no other process on this machine has claimed, and hold it.

    The claim lasts until the process exits. `preferred` is tried first. `program` names the
    holder in the lock (default: the script's name).
    """
    candidates = list(range(FIRST_DOMAIN_ID, LAST_DOMAIN_ID + 1))
    if preferred is not None and FIRST_DOMAIN_ID <= preferred <= LAST_DOMAIN_ID:
        candidates.remove(preferred)
        candidates.insert(0, preferred)
    else:
        # Spread start points so concurrent claimers rarely race for the same lock.
        offset = os.getpid() % len(candidates)
        candidates = candidates[offset:] + candidates[:offset]
    for domain_id in candidates:
        if _lock(domain_id, program or _this_program()):
            return domain_id
    raise RuntimeError(f"no free ROS_DOMAIN_ID in {FIRST_DOMAIN_ID}-{LAST_DOMAIN_ID}: "
                       f"every lock in {_lock_dir()} is held by a running process")


def local_graphs(program: str) -> list[tuple[int, int]]:
    """(domain id, pid) of each running process named `program` holding a domain lock."""
    found = []
    for path in sorted(_lock_dir().glob("domain-*.lock")):
        try:
            domain_id = int(path.stem.split("-", 1)[1])
            with open(path) as lock_file:
                try:  # a free lock: nobody runs there (released at once)
                    fcntl.flock(lock_file, fcntl.LOCK_SH | fcntl.LOCK_NB)
                    continue
                except OSError:
                    holder = json.loads(lock_file.read() or "{}")
        except (ValueError, OSError):  # not ours, unreadable, or written half-way
            continue
        if isinstance(holder, dict) and holder.get("program") == program:
            found.append((domain_id, int(holder.get("pid", 0))))
    return found


def check_domain_id(value: int | str, where: str = "ROS_DOMAIN_ID") -> int:
    """`value` as a domain id; ValueError naming `where` unless it is an integer in 0-232."""
    try:
        domain_id = int(str(value).strip())
    except ValueError:
        raise ValueError(f"{where} must be an integer in 0-{MAX_DOMAIN_ID}, got "
                         f"'{value}'") from None
    if not 0 <= domain_id <= MAX_DOMAIN_ID:
        raise ValueError(f"{where} must be within 0-{MAX_DOMAIN_ID} (DDS has no other "
                         f"domains), got {domain_id}")
    return domain_id


def environment_domain_id() -> int | None:
    """ROS_DOMAIN_ID from the environment (None if unset or empty); ValueError if invalid."""
    current = os.environ.get("ROS_DOMAIN_ID", "").strip()
    return check_domain_id(current, "ROS_DOMAIN_ID in the environment") if current else None


def isolate_local_graph(domain_id: int | None = None, log_dir: str | None = None,
                        program: str | None = None) -> int:
    """Set the environment for a loopback-only ROS graph on a private domain; return its id.

    With `domain_id` None: keep a non-zero ROS_DOMAIN_ID already set by the user, else claim a
    free one. A domain given is registered too when no process holds it (local_graphs finds
    it). `program` names this process there (default: the script's name). Discovery is
    restricted to localhost. Call before rclpy.init(). ValueError if `domain_id` or the
    environment's ROS_DOMAIN_ID is not an id DDS accepts (0-232).
    """
    if domain_id is not None:
        domain_id = check_domain_id(domain_id, "the domain id")
    else:
        domain_id = environment_domain_id() or None  # 0 is everyone's: claim a private one
    if domain_id is None:
        domain_id = claim_free_domain_id(program=program)
    else:
        _lock(domain_id, program or _this_program())  # held already: someone runs there
    os.environ["ROS_DOMAIN_ID"] = str(domain_id)
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    os.environ.pop("ROS_LOCALHOST_ONLY", None)  # deprecated in Jazzy; would conflict
    if log_dir is not None:
        os.environ["ROS_LOG_DIR"] = log_dir
    return domain_id


def describe_graph_settings() -> str:
    """One line naming the RMW, domain id and discovery range in effect (for startup logs)."""
    rmw = os.environ.get("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp (default)")
    domain = os.environ.get("ROS_DOMAIN_ID", "0 (default)")
    discovery = os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "SUBNET (default)")
    return f"RMW={rmw} ROS_DOMAIN_ID={domain} ROS_AUTOMATIC_DISCOVERY_RANGE={discovery}"
