"""Print the pins of the running environment for requirements.lock (used by `make lock`).

`pip freeze` is not usable here: the ros-jazzy-* wheels also install ament egg-info folders
(action_msgs, rclpy, ...) that look like distributions but do not exist on PyPI. Only
distributions that pip itself installed are pinned, never this project itself.

`--exclude FILE` leaves out the distributions FILE pins: requirements-cluster.lock holds only
what the cluster extra adds to requirements.lock.
"""
import json
import re
import subprocess
import sys


def _names(path):
    with open(path, encoding="utf-8") as stream:
        return {_normal(line.split("==")[0]) for line in stream
                if line.strip() and not line.startswith("#")}


def _normal(name):
    return re.sub(r"[-_.]+", "-", name.strip()).lower()


args = sys.argv[1:]
excluded = _names(args[1]) if args[:1] == ["--exclude"] else set()
excluded |= {"pip", "amr-wall-following"}
report = json.loads(subprocess.run([sys.executable, "-m", "pip", "inspect"], check=True,
                                   capture_output=True, text=True).stdout)
pins = sorted((p["metadata"]["name"], p["metadata"]["version"]) for p in report["installed"]
              if p.get("installer") == "pip"
              and _normal(p["metadata"]["name"]) not in excluded)
what = ("requirements-cluster.in on top of requirements.lock" if len(args) > 1
        else "requirements.in resolved")
print(f"# Pinned environment ({what} by `make lock`; do not edit by hand)")
for name, version in sorted(pins, key=lambda p: p[0].lower()):
    print(f"{name}=={version}")
