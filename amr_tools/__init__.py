"""amr_tools: whole programs on top of the shared layer, for any graph.

The `amr_foxglove_bridge` node (+ its handshake gate), the `amr_map_publisher` node, the MCAP
recorder and graph introspection (message classes by name, publisher-matched QoS: the scripts'
topic.py, lifecycle.py and ros_graph.py). Like an algorithm package it imports only amr_common
(and amr_msgs), so a tool works whatever filter, planner or controller runs; unlike one, nothing
below the scripts imports it (tests/test_layers.py).
"""
