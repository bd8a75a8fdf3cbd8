"""In-process rclpy harness used by the `ros` fixture (see conftest.py)."""
from __future__ import annotations

import time
from typing import Callable

import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node


class RosHarness:
    """One rclpy context + executor per test; nodes added to it are spun by spin_until/spin_for."""

    def __init__(self) -> None:
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self._nodes: list[Node] = []

    def node(self, name: str, **kwargs) -> Node:
        """Create a plain node in this context and spin it."""
        return self.add(Node(name, context=self.context, **kwargs))

    def add(self, node: Node) -> Node:
        """Spin an existing node (it must have been created with context=ros.context)."""
        self.executor.add_node(node)
        self._nodes.append(node)
        return node

    def spin_until(self, condition: Callable[[], bool], timeout: float = 10.0,
                   message: str = "condition") -> float:
        """Spin until condition() is true; fail the test after `timeout` seconds.

        Returns the seconds it took.
        """
        start = time.monotonic()
        while not condition():
            elapsed = time.monotonic() - start
            if elapsed > timeout:
                pytest.fail(f"timed out after {timeout:.1f} s waiting for {message}")
            self.executor.spin_once(timeout_sec=min(0.05, max(timeout - elapsed, 0.001)))
        return time.monotonic() - start

    def bring_up(self, node, discovered: Callable[[], bool], timeout: float = 10.0) -> None:
        """Configure and activate a lifecycle node, then spin until `discovered()` and a bit.

        `discovered()`: the test's publishers and subscribers matched.
        """
        assert node.trigger_configure().name == "SUCCESS"
        assert node.trigger_activate().name == "SUCCESS"
        self.spin_until(discovered, timeout, "discovery")
        self.spin_for(0.2)

    def spin_for(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=min(0.05, max(end - time.monotonic(), 0.001)))

    def close(self) -> None:
        for node in reversed(self._nodes):
            try:
                self.executor.remove_node(node)
                node.destroy_node()
            except Exception:  # a node a test already destroyed
                pass
        self.executor.shutdown(timeout_sec=1.0)
        if self.context.ok():
            rclpy.shutdown(context=self.context)
