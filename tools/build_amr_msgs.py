"""Build a ROS 2 interface package (amr_msgs by default) into the running virtual environment.

Plain CMake, no colcon: the rosidl generators come from the PyPI ros-jazzy-* wheels and the
package is installed into the venv prefix, so `from amr_msgs.msg import PoseStamped` works with
nothing to source. The PyPI-specific fixes live in tools/cmake/ros_pypi_wheels.cmake and are
injected with CMAKE_PROJECT_<name>_INCLUDE; the package itself stays a standard ament package.
Usage (the Makefile calls it when sources change):
  .venv/bin/python tools/build_amr_msgs.py                      # amr_msgs
  .venv/bin/python tools/build_amr_msgs.py third_party/tf2_msgs --unless-provided
`--unless-provided`: do nothing when the package's Python module is importable from outside this
venv (an apt ROS install sourced: it keeps its own, the same definition).
"""
from __future__ import annotations

import argparse
import importlib.util
import os
import shutil
import subprocess
import sys
import sysconfig
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def provided_elsewhere(package: str, prefix: Path) -> str | None:
    """Where `package` is importable from outside `prefix` (e.g. /opt/ros/jazzy), else None."""
    try:
        spec = importlib.util.find_spec(package)
    except (ImportError, ValueError):
        return None
    locations = list(spec.submodule_search_locations or []) if spec else []
    outside = [p for p in locations if not Path(p).resolve().is_relative_to(prefix.resolve())]
    return outside[0] if outside else None


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="Build a ROS 2 interface package into the venv")
    parser.add_argument("package_dir", nargs="?", default=str(REPO / "amr_msgs"),
                        help="folder of the ament interface package (default amr_msgs)")
    parser.add_argument("--unless-provided", action="store_true",
                        help="skip when the package is importable from outside this venv")
    args = parser.parse_args(argv)
    source = Path(args.package_dir).resolve()
    name = source.name
    prefix = Path(sys.prefix)
    if prefix == Path(sys.base_prefix):
        print("build_amr_msgs: run this with the virtual environment's python", file=sys.stderr)
        return 2
    if args.unless_provided:
        elsewhere = provided_elsewhere(name, prefix)
        if elsewhere:
            print(f"build_amr_msgs: {name} is provided by {elsewhere}: not building it")
            return 0
    if shutil.which("cmake") is None:
        print("build_amr_msgs: cmake not found on PATH", file=sys.stderr)
        return 2
    build_dir = REPO / "build" / f"{name}-py{sys.version_info.major}{sys.version_info.minor}"
    if build_dir.exists():
        shutil.rmtree(build_dir)  # a clean build: stale generated files cause odd errors
    env = dict(os.environ, AMENT_PREFIX_PATH=str(prefix), CMAKE_PREFIX_PATH=str(prefix))
    # Quiet the ament test macros; the generators want the venv's tools first on PATH.
    env["PATH"] = f"{prefix / 'bin'}{os.pathsep}{env.get('PATH', '')}"
    configure = [
        "cmake", "-S", str(source), "-B", str(build_dir),
        f"-DCMAKE_PREFIX_PATH={prefix}",
        f"-DCMAKE_INSTALL_PREFIX={prefix}",
        f"-DPython3_EXECUTABLE={sys.executable}",
        f"-DPython3_INCLUDE_DIR={sysconfig.get_paths()['include']}",
        "-DBUILD_TESTING=OFF",
        "-DCMAKE_BUILD_TYPE=Release",
        f"-DCMAKE_PROJECT_{name}_INCLUDE={REPO / 'tools' / 'cmake' / 'ros_pypi_wheels.cmake'}",
    ]
    jobs = str(os.cpu_count() or 2)
    steps = [configure, ["cmake", "--build", str(build_dir), "-j", jobs],
             ["cmake", "--install", str(build_dir)]]
    start = time.monotonic()
    log_path = build_dir.parent / f"{name}-build.log"
    log_path.parent.mkdir(parents=True, exist_ok=True)
    with open(log_path, "w") as log:
        for cmd in steps:
            log.write("$ " + " ".join(cmd) + "\n")
            log.flush()
            result = subprocess.run(cmd, env=env, stdout=log, stderr=subprocess.STDOUT)
            if result.returncode != 0:
                log.close()
                print(log_path.read_text()[-4000:], file=sys.stderr)
                print(f"build_amr_msgs: '{' '.join(cmd[:2])}' failed; full log: {log_path}",
                      file=sys.stderr)
                return 1
    print(f"build_amr_msgs: {name} built and installed into {prefix} "
          f"in {time.monotonic() - start:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
