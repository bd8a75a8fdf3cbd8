"""Build the amr_msgs interface package into the running virtual environment.

Plain CMake, no colcon: the rosidl generators come from the PyPI ros-jazzy-* wheels and the
package is installed into the venv prefix, so `from amr_msgs.msg import PoseStamped` works with
nothing to source. The PyPI-specific fixes live in tools/cmake/ros_pypi_wheels.cmake and are
injected with CMAKE_PROJECT_amr_msgs_INCLUDE; amr_msgs/ itself stays a standard ament package.
Usage: .venv/bin/python tools/build_amr_msgs.py   (the Makefile calls it when sources change)
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def main() -> int:
    prefix = Path(sys.prefix)
    if prefix == Path(sys.base_prefix):
        print("build_amr_msgs: run this with the virtual environment's python", file=sys.stderr)
        return 2
    if shutil.which("cmake") is None:
        print("build_amr_msgs: cmake not found on PATH", file=sys.stderr)
        return 2
    build_dir = REPO / "build" / f"amr_msgs-py{sys.version_info.major}{sys.version_info.minor}"
    if build_dir.exists():
        shutil.rmtree(build_dir)  # a clean build: stale generated files cause odd errors
    env = dict(os.environ, AMENT_PREFIX_PATH=str(prefix), CMAKE_PREFIX_PATH=str(prefix))
    # Quiet the ament test macros; the generators want the venv's tools first on PATH.
    env["PATH"] = f"{prefix / 'bin'}{os.pathsep}{env.get('PATH', '')}"
    configure = [
        "cmake", "-S", str(REPO / "amr_msgs"), "-B", str(build_dir),
        f"-DCMAKE_PREFIX_PATH={prefix}",
        f"-DCMAKE_INSTALL_PREFIX={prefix}",
        f"-DPython3_EXECUTABLE={sys.executable}",
        f"-DPython3_INCLUDE_DIR={sysconfig.get_paths()['include']}",
        "-DBUILD_TESTING=OFF",
        "-DCMAKE_BUILD_TYPE=Release",
        f"-DCMAKE_PROJECT_amr_msgs_INCLUDE={REPO / 'tools' / 'cmake' / 'ros_pypi_wheels.cmake'}",
    ]
    jobs = str(os.cpu_count() or 2)
    steps = [configure, ["cmake", "--build", str(build_dir), "-j", jobs],
             ["cmake", "--install", str(build_dir)]]
    start = time.monotonic()
    log_path = build_dir.parent / "amr_msgs-build.log"
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
    print(f"build_amr_msgs: amr_msgs built and installed into {prefix} "
          f"in {time.monotonic() - start:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
