// Foxglove's own JavaScript client (@foxglove/ws-protocol's FoxgloveClient, which offers only
// the "foxglove.websocket.v1" subprotocol, as Lichtblick does) against the bridge: decodes the
// first /scan and /map with @foxglove/rosmsg2-serialization and publishes /initialpose.
// Prints one JSON line per decoded topic, then "published"; exit 1 on any failure.
//   node tests/foxglove_js/client.mjs ws://127.0.0.1:PORT
import { parse } from "@foxglove/rosmsg";
import { MessageReader, MessageWriter } from "@foxglove/rosmsg2-serialization";
import wsProtocol from "@foxglove/ws-protocol"; // CommonJS: no named exports for Node's ESM
import WebSocket from "ws";

const { FoxgloveClient } = wsProtocol;

const INITIAL_POSE_DEFINITION = `
std_msgs/Header header
geometry_msgs/PoseWithCovariance pose
================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
================================================================================
MSG: geometry_msgs/PoseWithCovariance
geometry_msgs/Pose pose
float64[36] covariance
================================================================================
MSG: geometry_msgs/Pose
geometry_msgs/Point position
geometry_msgs/Quaternion orientation
================================================================================
MSG: geometry_msgs/Point
float64 x
float64 y
float64 z
================================================================================
MSG: geometry_msgs/Quaternion
float64 x
float64 y
float64 z
float64 w
`;

const fail = (why) => {
  console.error(`foxglove_js client: ${why}`);
  process.exit(1);
};
setTimeout(() => fail("timed out"), 20000);

const numbers = (values) => Array.from(values, (v) => (Number.isNaN(v) ? null : v));
const summaries = {
  "/scan": (m) => ({ frame_id: m.header.frame_id, stamp: m.header.stamp,
    angle_min: m.angle_min, angle_increment: m.angle_increment, ranges: numbers(m.ranges) }),
  "/map": (m) => ({ width: m.info.width, height: m.info.height, data: numbers(m.data) }),
};

const client = new FoxgloveClient({
  ws: new WebSocket(process.argv[2], [FoxgloveClient.SUPPORTED_SUBPROTOCOL]),
});
const readers = new Map(); // subscription id -> [topic, MessageReader]
const decoded = new Set();
client.on("error", (error) => fail(`error: ${error?.message ?? error}`));
client.on("close", () => decoded.size < 2 && fail("the server closed the connection"));
client.on("advertise", (channels) => {
  for (const channel of channels) {
    if (!(channel.topic in summaries) || channel.encoding !== "cdr") continue;
    const reader = new MessageReader(parse(channel.schema, { ros2: true }));
    readers.set(client.subscribe(channel.id), [channel.topic, reader]);
  }
});
client.on("message", ({ subscriptionId, data }) => {
  const [topic, reader] = readers.get(subscriptionId) ?? [];
  if (topic === undefined || decoded.has(topic)) return;
  decoded.add(topic);
  console.log(JSON.stringify({ topic, message: summaries[topic](reader.readMessage(data)) }));
  if (decoded.size === 2) publishInitialPose();
});

function publishInitialPose() {
  const channel = client.advertise({ topic: "/initialpose", encoding: "cdr",
    schemaName: "geometry_msgs/msg/PoseWithCovarianceStamped" });
  const writer = new MessageWriter(parse(INITIAL_POSE_DEFINITION, { ros2: true }));
  const data = writer.writeMessage({
    header: { stamp: { sec: 3, nanosec: 0 }, frame_id: "map" },
    pose: { pose: { position: { x: 0.75, y: -0.5, z: 0 },
      orientation: { x: 0, y: 0, z: 0, w: 1 } }, covariance: new Array(36).fill(0) },
  });
  let sent = 0;
  const timer = setInterval(() => { // until the test has seen one (it stops us) or 3 s
    client.sendMessage(channel, data);
    if (++sent === 30) {
      clearInterval(timer);
      console.log("published");
      process.exit(0);
    }
  }, 100);
}
