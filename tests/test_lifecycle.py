"""scripts/lifecycle.py against a lifecycle node: get, set, and a node that does not answer."""
from __future__ import annotations

import subprocess
import sys

import pytest
from rclpy.parameter import Parameter

from amr_tools.map_publisher import MapPublisherNode
from tests.processes import REPO, run_script_while_spinning

sys.path.insert(0, str(REPO / "scripts"))
import lifecycle  # noqa: E402


@pytest.mark.slow
def test_lifecycle_tool_gets_and_sets_states(ros):
    # A name no other test uses: a node of an earlier test may linger in the graph for a while.
    node = ros.add(MapPublisherNode("lifecycle_tool_target", context=ros.context,
                                    parameter_overrides=[Parameter("world", value="lab02")]))
    out = run_script_while_spinning(ros, "scripts/lifecycle.py", "get", "lifecycle_tool_target")
    assert out.strip() == "unconfigured [1]"
    out = run_script_while_spinning(ros, "scripts/lifecycle.py", "set", "lifecycle_tool_target",
                                    "configure")
    assert "successful" in out
    assert node._state_machine.current_state[1] == "inactive"
    process = subprocess.run([sys.executable, "scripts/lifecycle.py", "set",
                              "lifecycle_tool_target", "activate", "--timeout", "1"],
                             capture_output=True, text=True, cwd=REPO, timeout=30)
    assert process.returncode == 1  # nobody spins the node now: no answer, a clear exit code


@pytest.mark.parametrize("argv", [
    ["get", "wall_follower", "--timeout", "-1"], ["get", "wall_follower", "--timeout", "nan"],
    ["nodes", "--timeout", "0"], ["list", "wall_follower", "--timeout", "inf"],
    ["get", "wall follower"], ["set", "/wall_follower/", "activate"], ["set", "wall_follower"]])
def test_command_line_mistakes_are_one_line_errors(argv, capsys):
    """A negative timeout waited forever for the services; a bad name ended in a traceback."""
    with pytest.raises(SystemExit) as stopped:
        lifecycle.parse_args(argv)
    assert stopped.value.code == 2
    assert "error: " in capsys.readouterr().err.splitlines()[-1]
