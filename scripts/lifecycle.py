#!/usr/bin/env python3
"""Lifecycle tools without ros2cli: see and change the state of managed nodes.

  .venv/bin/python scripts/lifecycle.py nodes                     # nodes with a lifecycle
  .venv/bin/python scripts/lifecycle.py get wall_follower         # e.g. "active [3]"
  .venv/bin/python scripts/lifecycle.py list wall_follower        # transitions possible now
  .venv/bin/python scripts/lifecycle.py set wall_follower deactivate
Transitions by label (configure, activate, deactivate, cleanup, shutdown) or id. Uses the
current ROS_DOMAIN_ID (or --domain-id). Exit code 1 when the node does not answer within
--timeout or refuses the transition, 2 for a mistake in the command line.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from amr_tools.introspection import GraphProbe  # noqa: E402
from cli_checks import (  # noqa: E402
    add_domain_id_option,
    number_argument,
    ros_name_argument,
    use_domain_id,
)


def parse_args(argv=None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter,
                                     epilog=__doc__.split("\n", 1)[1])
    add_domain_id_option(parser)
    timeout = argparse.ArgumentParser(add_help=False)
    timeout.add_argument("--timeout", type=number_argument(float, 0.0, above=True, maximum=3600),
                         default=5.0, help="seconds to wait for the node's services (default 5)")
    commands = parser.add_subparsers(dest="command", required=True)
    commands.add_parser("nodes", help="nodes offering lifecycle services", parents=[timeout])
    node_name = ros_name_argument("node")
    for name, text in (("get", "current state"), ("list", "available transitions")):
        commands.add_parser(name, help=text, parents=[timeout]).add_argument("node",
                                                                             type=node_name)
    setter = commands.add_parser("set", help="trigger a transition", parents=[timeout])
    setter.add_argument("node", type=node_name)
    setter.add_argument("transition", help="label (configure, activate, ...) or id")
    return parser.parse_args(argv)


class LifecycleClient(GraphProbe):
    """Calls a node's <node>/get_state, get_available_transitions and change_state."""

    def __init__(self, timeout: float) -> None:
        super().__init__("lifecycle_tool")
        self.timeout = timeout

    def call(self, service_type, name: str, request, attempts: int = 1):
        """The response, or None (and a message) if the service does not answer in time.

        Queries (`attempts` > 1) are sent again when unanswered: a request can go to a node
        that has just left the graph while the new one is still being discovered.
        """
        client = self.node.create_client(service_type, name)
        try:
            if not client.wait_for_service(timeout_sec=self.timeout):
                print(f"no service {name} within {self.timeout} s: is the node running on "
                      f"this ROS_DOMAIN_ID?", file=sys.stderr)
                return None
            for _ in range(attempts):
                future = client.call_async(request)
                self.executor.spin_until_future_complete(future,
                                                         timeout_sec=self.timeout / attempts)
                if future.done():
                    return future.result()
            print(f"{name} did not answer within {self.timeout} s", file=sys.stderr)
            return None
        finally:
            self.node.destroy_client(client)

    def lifecycle_nodes(self, wait: float = 2.0) -> list[str]:
        self.spin(wait)
        return sorted(name.rsplit("/get_state", 1)[0] for name, types in
                      self.node.get_service_names_and_types()
                      if name.endswith("/get_state") and "lifecycle_msgs/srv/GetState" in types)


def main(argv=None) -> int:
    args = parse_args(argv)
    use_domain_id(args)
    from lifecycle_msgs.msg import Transition
    from lifecycle_msgs.srv import ChangeState, GetAvailableTransitions, GetState
    tool = LifecycleClient(args.timeout)
    try:
        if args.command == "nodes":
            for name in tool.lifecycle_nodes():
                print(name)
            return 0
        if args.command == "get":
            response = tool.call(GetState, f"{args.node}/get_state", GetState.Request(),
                                 attempts=3)
            if response is None:
                return 1
            print(f"{response.current_state.label} [{response.current_state.id}]")
            return 0
        available = tool.call(GetAvailableTransitions, f"{args.node}/get_available_transitions",
                              GetAvailableTransitions.Request(), attempts=3)
        if available is None:
            return 1
        transitions = [d.transition for d in available.available_transitions]
        if args.command == "list":
            for d in available.available_transitions:
                print(f"- {d.transition.label} [{d.transition.id}]: {d.start_state.label} -> "
                      f"{d.goal_state.label}")
            return 0
        wanted = args.transition.strip()
        matching = [t for t in transitions if t.label == wanted or str(t.id) == wanted]
        if not matching:
            labels = ", ".join(t.label for t in transitions) or "none"
            print(f"'{wanted}' is not possible now (available: {labels})", file=sys.stderr)
            return 1
        request = ChangeState.Request(transition=Transition(id=matching[0].id))
        response = tool.call(ChangeState, f"{args.node}/change_state", request)
        if response is None or not response.success:
            print(f"transition '{wanted}' failed", file=sys.stderr)
            return 1
        print(f"transition '{wanted}' successful")
        return 0
    except KeyboardInterrupt:
        return 1
    finally:
        tool.close()


if __name__ == "__main__":
    from script_endings import run_script  # a closed output loses nothing
    sys.exit(run_script(main))
