"""The house rules: amr_common at the bottom, algorithm packages beside it, harness on top.

Algorithm packages sit beside each other (never importing one another); the evaluation harness
and the scripts sit above them. amr_tools (whole programs: Foxglove bridge, map publisher, MCAP
recorder, introspection) imports only the shared layer, like an algorithm, and nothing below the
scripts imports it.
"""
from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
SHARED = "amr_common"
ALGORITHM_PACKAGES = ["amr_sim", "amr_control", "amr_turtlebot3", "amr_localization",
                      "amr_planning", "amr_mapping"]
HARNESS = "amr_evaluation"
TOOLS = "amr_tools"


def imported_amr_packages(package: str) -> dict[str, set[str]]:
    """{module path: top-level amr_* packages it imports} for every module of `package`."""
    found: dict[str, set[str]] = {}
    for path in sorted((REPO / package).rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        names = set()
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                names.update(alias.name.split(".")[0] for alias in node.names)
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names.add(node.module.split(".")[0])
        found[str(path.relative_to(REPO))] = {n for n in names if n.startswith("amr_")}
    return found


def test_shared_layer_imports_only_itself():
    for module, names in imported_amr_packages(SHARED).items():
        assert names <= {SHARED}, f"{module} imports {sorted(names - {SHARED})}"


@pytest.mark.parametrize("package", [p for p in ALGORITHM_PACKAGES if (REPO / p).is_dir()])
def test_algorithm_packages_import_only_the_shared_layer(package):
    allowed = {SHARED, package, "amr_msgs"}
    for module, names in imported_amr_packages(package).items():
        assert names <= allowed, f"{module} imports {sorted(names - allowed)}"


def test_tools_import_only_the_shared_layer():
    allowed = {SHARED, TOOLS, "amr_msgs"}
    for module, names in imported_amr_packages(TOOLS).items():
        assert names <= allowed, f"{module} imports {sorted(names - allowed)}"


@pytest.mark.parametrize("package", [SHARED, *ALGORITHM_PACKAGES, HARNESS])
def test_nothing_below_the_scripts_imports_the_tools(package):
    for module, names in imported_amr_packages(package).items():
        assert TOOLS not in names, f"{module} imports {TOOLS}"


def test_harness_imports_no_script():
    for module, names in imported_amr_packages(HARNESS).items():
        assert "launch_common" not in names and "sim_session" not in names, module


def test_simulator_node_loads_no_controller_code():
    code = ("import amr_sim.simulator_node, sys; "
            "bad = [m for m in sys.modules if m.startswith('amr_control')]; "
            "assert not bad, bad")
    subprocess.run([sys.executable, "-c", code], check=True, cwd=REPO, timeout=120)
