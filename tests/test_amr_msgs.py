"""amr_msgs is a real ROS interface: it publishes and subscribes like any message."""
from amr_msgs.msg import PoseStamped


def test_pose_stamped_round_trips_over_dds(ros):
    node = ros.node("amr_msgs_round_trip")
    received = []
    node.create_subscription(PoseStamped, "pose_round_trip", received.append, 10)
    publisher = node.create_publisher(PoseStamped, "pose_round_trip", 10)
    sent = PoseStamped()
    sent.header.stamp.sec = 12
    sent.header.stamp.nanosec = 500
    sent.header.frame_id = "map"
    sent.pose.position.x = 1.25
    sent.pose.position.y = -0.5
    sent.pose.orientation.z = 0.70710678
    sent.pose.orientation.w = 0.70710678
    sent.localized = True

    def published_and_received() -> bool:
        publisher.publish(sent)
        return bool(received)

    ros.spin_until(published_and_received, timeout=10.0, message="PoseStamped to arrive")
    got = received[0]
    assert got == sent
    assert PoseStamped.__module__.startswith("amr_msgs.msg")
    topic_types = dict(node.get_topic_names_and_types())
    assert topic_types["/pose_round_trip"] == ["amr_msgs/msg/PoseStamped"]
