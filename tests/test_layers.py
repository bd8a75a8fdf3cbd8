"""The house rules: amr_common at the bottom, algorithm packages beside it, harness on top.

Algorithm packages sit beside each other (never importing one another); the evaluation harness
and the scripts sit above them. amr_tools (whole programs: Foxglove bridge, map publisher, MCAP
recorder, introspection) imports only the shared layer, like an algorithm, and nothing below the
scripts imports it. examples/ (a student's links) sits on top like the scripts: it imports only
the shared layer (a replacement needs nothing else), and nothing of the project imports it.
Inside amr_common, only its ros/ subpackage imports ROS (rclpy, message packages): interfaces,
worlds and sensor models stay plain Python. No amr_* module imports itself through others (an
import circle), whether the imports sit at the top of a module, in a function or under
TYPE_CHECKING: a circle is a layering inside a package that nobody can read top-down, and a
lazy import only hides it.
"""
from __future__ import annotations

import ast
import subprocess
import sys
from collections import deque
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
SHARED = "amr_common"
ALGORITHM_PACKAGES = ["amr_sim", "amr_control", "amr_turtlebot3", "amr_localization",
                      "amr_planning", "amr_mapping"]
HARNESS = "amr_evaluation"
TOOLS = "amr_tools"
EXAMPLES = "examples"  # course-style links: on top like the scripts, on the shared layer only


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
        found[str(path.relative_to(REPO))] = {n for n in names
                                              if n.startswith("amr_") or n == EXAMPLES}
    return found


def _module_name(root: Path, path: Path) -> str:
    parts = path.relative_to(root).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def import_graph(root: Path) -> dict[str, set[str]]:
    """{amr_* module: the amr_* modules it imports} of the packages in `root`.

    Every import statement counts (module top level, functions, TYPE_CHECKING blocks).
    `from package import name` is an import of the module package.name when there is one, else
    of the package; relative imports are resolved against the importing module's package.
    """
    files = {_module_name(root, path): path
             for package in sorted(root.glob("amr_*/__init__.py"))
             for path in sorted(package.parent.rglob("*.py"))}
    graph: dict[str, set[str]] = {}
    for module, path in files.items():
        package = module if path.name == "__init__.py" else module.rpartition(".")[0]
        targets: set[str] = set()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
            if isinstance(node, ast.Import):
                for alias in node.names:
                    parts = alias.name.split(".")
                    targets.update([".".join(parts[:n]) for n in range(len(parts), 0, -1)
                                    if ".".join(parts[:n]) in files][:1])
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    anchor = package.split(".")[:len(package.split(".")) - (node.level - 1)]
                    base = ".".join(anchor + ([node.module] if node.module else []))
                for alias in node.names:
                    if f"{base}.{alias.name}" in files:
                        targets.add(f"{base}.{alias.name}")
                    elif base in files:
                        targets.add(base)
        graph[module] = targets - {module}
    return graph


def import_circles(graph: dict[str, set[str]]) -> list[tuple[list[str], set[str]]]:
    """(a circle [a, b, ..., a], its group) for each group of modules that import each other.

    A group: modules each of which imports every other through the others (a strongly
    connected component); the circle is the shortest one from its first module.
    """
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    groups: list[set[str]] = []

    def visit(module: str) -> None:  # Tarjan's strongly connected components
        index[module] = low[module] = len(index)
        stack.append(module)
        for target in sorted(graph.get(module, ())):
            if target not in index:
                visit(target)
                low[module] = min(low[module], low[target])
            elif target in stack:
                low[module] = min(low[module], index[target])
        if low[module] == index[module]:
            group = set()
            while True:
                member = stack.pop()
                group.add(member)
                if member == module:
                    break
            if len(group) > 1:
                groups.append(group)

    for module in sorted(graph):
        if module not in index:
            visit(module)
    circles = []
    for group in groups:  # the shortest way from the group's first module back to it
        start = min(group)
        paths = {start: [start]}
        queue = deque([start])
        while queue:
            module = queue.popleft()
            if start in graph[module]:
                circles.append((paths[module] + [start], group))
                break
            for target in sorted(graph[module] & group):
                if target not in paths:
                    paths[target] = paths[module] + [target]
                    queue.append(target)
    return circles


def test_no_import_circle_among_the_amr_modules():
    circles = import_circles(import_graph(REPO))
    assert not circles, "import circles:\n" + "\n".join(
        f"{' -> '.join(circle)} (in a group of {len(group)}: {', '.join(sorted(group))})"
        for circle, group in circles)


def test_the_circle_check_finds_a_circle_through_a_function_and_a_relative_import(tmp_path):
    package = tmp_path / "amr_made_up"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "maps.py").write_text("from amr_made_up.worlds import World\n")
    (package / "worlds.py").write_text("def load():\n    from .files import read\n")
    (package / "files.py").write_text("import amr_made_up.maps as maps\n")
    (package / "plain.py").write_text("from amr_made_up import files\n")  # into it, not in it
    graph = import_graph(tmp_path)
    assert graph["amr_made_up.plain"] == {"amr_made_up.files"}
    names = ["amr_made_up.files", "amr_made_up.maps", "amr_made_up.worlds"]
    assert import_circles(graph) == [([*names, "amr_made_up.files"], set(names))]
    (package / "worlds.py").write_text("def load():\n    return None\n")
    assert import_circles(import_graph(tmp_path)) == []


def test_shared_layer_imports_only_itself():
    for module, names in imported_amr_packages(SHARED).items():
        assert names <= {SHARED}, f"{module} imports {sorted(names - {SHARED})}"


def test_only_the_shared_layers_ros_subpackage_imports_ros():
    for path in sorted((REPO / SHARED).rglob("*.py")):
        if path.relative_to(REPO / SHARED).parts[0] == "ros":
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        names = {alias.name.split(".")[0] for node in ast.walk(tree)
                 if isinstance(node, ast.Import) for alias in node.names}
        names |= {node.module.split(".")[0] for node in ast.walk(tree)
                  if isinstance(node, ast.ImportFrom) and node.module and node.level == 0}
        ros = sorted(n for n in names if n in ("rclpy", "tf2_ros") or n.endswith("_msgs"))
        assert not ros, f"{path.relative_to(REPO)} imports {ros}: its home is {SHARED}/ros/"


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


def test_examples_import_only_the_shared_layer():
    for module, names in imported_amr_packages(EXAMPLES).items():
        assert names <= {SHARED, EXAMPLES}, f"{module} imports {sorted(names - {SHARED})}"


@pytest.mark.parametrize("package", [SHARED, *ALGORITHM_PACKAGES, HARNESS, TOOLS, "scripts"])
def test_nothing_of_the_project_imports_the_examples(package):
    for module, names in imported_amr_packages(package).items():
        assert EXAMPLES not in names, f"{module} imports {EXAMPLES}"
