"""`grapefmu replay run.mcap --publish [--rate X]`: republish a recording's topics, paced by their log
times (rate 1 = real time, 0 = as fast as possible), with /clock.

The recorded CDR bytes (written through grapefmu's one typestore) are published as they are."""
from __future__ import annotations

import time

import rclpy
from rclpy.duration import Duration
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock

from grapefmu.recording import messages as msgs
from grapefmu.recording.replay import iter_messages
from grapefmu.recording.stamps import seconds
from grapefmu.recording.typestore import serialize

from .interfaces import message_class
from .qos import for_recorded

QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=ReliabilityPolicy.RELIABLE)


#: Discovery before playing (like rosbag2 play --delay): at least MIN, then until a subscriber has matched,
#: at most MAX. A listener that announced itself just before the replayer started is only seen at its
#: next periodic announcement, so a fixed short delay missed it about half the time.
DISCOVERY_MIN_S, DISCOVERY_MAX_S = 1.0, 5.0


def _publishers(node, path: str) -> dict:
    """One publisher per recorded topic, created before playing so discovery can match them first."""
    pubs = {}
    with open(path, "rb") as fh:
        try:
            for schema, ch, _ in iter_messages(fh):
                if ch.topic != "/clock" and ch.topic not in pubs:
                    cls = message_class(schema.name)
                    pubs[ch.topic] = (node.create_publisher(cls, ch.topic, for_recorded(ch.topic, QOS)), cls)
        except Exception:  # noqa: BLE001 - a torn end: the topics seen so far
            pass
    return pubs


def publish(path: str, rate: float = 1.0) -> int:
    rclpy.init()
    node = rclpy.create_node("grapefmu_replay")
    clock = node.create_publisher(Clock, "/clock", 10)
    pubs = _publishers(node, path)
    t0 = time.monotonic()
    while time.monotonic() - t0 < DISCOVERY_MAX_S:
        rclpy.spin_once(node, timeout_sec=0.05)
        if time.monotonic() - t0 > DISCOVERY_MIN_S and any(p.get_subscription_count() for p, _ in pubs.values()):
            break
    n = 0
    try:
        with open(path, "rb") as fh:
            wall0 = time.monotonic()
            t0 = None
            try:
                for schema, ch, r in iter_messages(fh):
                    if ch.topic not in pubs:
                        continue
                    t0 = r.log_time if t0 is None else t0
                    if rate > 0:
                        delay = seconds(r.log_time - t0) / rate - (time.monotonic() - wall0)
                        if delay > 0:
                            time.sleep(delay)
                    clock.publish(serialize(msgs.clock(r.log_time)[1]))
                    pubs[ch.topic][0].publish(bytes(r.data))
                    n += 1
            except Exception as e:  # noqa: BLE001 - a torn end: report, keep what was published
                print(f"warning: {path} ends abruptly ({type(e).__name__}); stopped after {n} messages")
        # reliable delivery is asynchronous: exiting now would drop what subscribers have not yet acknowledged
        for pub, _ in pubs.values():
            pub.wait_for_all_acked(Duration(seconds=5.0))
    finally:
        node.destroy_node()
        rclpy.shutdown()
    print(f"republished {n} messages on {len(pubs)} topics from {path}")
    return 0
