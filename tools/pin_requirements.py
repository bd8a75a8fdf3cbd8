"""Print the pins of the running environment for requirements.lock (used by `make lock`).

`pip freeze` is not usable here: the ros-jazzy-* wheels also install ament egg-info folders
(action_msgs, rclpy, ...) that look like distributions but do not exist on PyPI. Only
distributions that pip itself installed are pinned.
"""
import json
import subprocess
import sys

report = json.loads(subprocess.run([sys.executable, "-m", "pip", "inspect"], check=True,
                                   capture_output=True, text=True).stdout)
pins = sorted((p["metadata"]["name"], p["metadata"]["version"]) for p in report["installed"]
              if p.get("installer") == "pip" and p["metadata"]["name"].lower() != "pip")
print("# Pinned environment (requirements.in resolved by `make lock`; do not edit by hand)")
for name, version in sorted(pins, key=lambda p: p[0].lower()):
    print(f"{name}=={version}")
