"""Print the pins of the running environment for requirements.lock (used by `make lock`).

`pip freeze` is not usable here: the ros-jazzy-* wheels also install ament egg-info folders
(action_msgs, rclpy, ...) that look like distributions but do not exist on PyPI. Only
distributions that pip itself installed are pinned, never this project itself.

`--exclude FILE` (repeatable) leaves out the distributions FILE pins: requirements-cluster.lock
holds only what the cluster extra adds to requirements.lock, requirements-docs.lock only what
the manual's build adds to both. `--source TEXT` names what was resolved in the header line.
"""
import argparse
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


parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--exclude", action="append", default=[], metavar="FILE")
parser.add_argument("--source", default=None, metavar="TEXT")
args = parser.parse_args()
excluded = {"pip", "amr-wall-following"}
for path in args.exclude:
    excluded |= _names(path)
report = json.loads(subprocess.run([sys.executable, "-m", "pip", "inspect"], check=True,
                                   capture_output=True, text=True).stdout)
pins = sorted((p["metadata"]["name"], p["metadata"]["version"]) for p in report["installed"]
              if p.get("installer") == "pip"
              and _normal(p["metadata"]["name"]) not in excluded)
what = args.source or "requirements.in resolved"
print(f"# Pinned environment ({what} by `make lock`; do not edit by hand)")
for name, version in sorted(pins, key=lambda p: p[0].lower()):
    print(f"{name}=={version}")
