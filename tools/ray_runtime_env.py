"""Build a wheel of the project and a Ray runtime_env that installs it on a cluster's workers.

    .venv/bin/python tools/ray_runtime_env.py            # -> dist/runtime_env.json
    .venv/bin/python scripts/evaluate.py --ray auto --ray-runtime-env dist/runtime_env.json ...

For clusters whose nodes do not share this venv: Ray uploads the wheel (py_modules) and, once
per node, pip-installs the packages the episodes import at the versions requirements.lock pins
into a virtualenv of its own (the nodes need `ray` of the same version as here, `virtualenv`,
and access to PyPI). Episodes import no ROS: amr_msgs and the ros-jazzy wheels are not needed
on the workers.
"""
from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
# What amr_evaluation's episodes import (simulator, controllers, particle filter), with the
# dependencies pip would pull in, so every version is the lock's.
EPISODE_PACKAGES = ("numpy", "pymunk", "cffi", "pycparser", "numba", "llvmlite", "pyyaml",
                    "transforms3d")


def pins(lock: Path) -> list[str]:
    found = {}
    for line in lock.read_text(encoding="utf-8").splitlines():
        name, sep, version = line.strip().partition("==")
        if sep:
            found[re.sub(r"[-_.]+", "-", name).lower()] = f"{name}=={version}"
    missing = [p for p in EPISODE_PACKAGES if p not in found]
    if missing:
        raise SystemExit(f"{lock} pins none of {', '.join(missing)}")
    return [found[p] for p in EPISODE_PACKAGES]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--dist", default=str(REPO / "dist"), help="output folder (dist/)")
    args = parser.parse_args(argv)
    dist = Path(args.dist).resolve()
    dist.mkdir(parents=True, exist_ok=True)
    for old in dist.glob("amr_wall_following-*.whl"):
        old.unlink()
    subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps",
                    "--no-build-isolation", "-w", str(dist), str(REPO)], check=True)
    (wheel,) = dist.glob("amr_wall_following-*.whl")
    runtime_env = {"py_modules": [str(wheel)], "pip": pins(REPO / "requirements.lock")}
    target = dist / "runtime_env.json"
    target.write_text(json.dumps(runtime_env, indent=1) + "\n", encoding="utf-8")
    print(f"{target}: {wheel.name} + {', '.join(runtime_env['pip'])}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
