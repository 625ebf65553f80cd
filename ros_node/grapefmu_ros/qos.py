"""Quality of service per topic, for the node and for `replay --publish`, which republishes the node's topics."""
from __future__ import annotations

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

EVENTS_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.VOLATILE)
STATE_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100, reliability=ReliabilityPolicy.RELIABLE)
#: latched: a late subscriber (RViz, robot_state_publisher, a tf2 buffer) still gets them
LATCHED_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
#: inputs per mode: best effort, which matches both reliable and best-effort (sensor-data) publishers. Real time
#: holds the newest input. Lockstep steps once per input and answers each, so it keeps LOCKSTEP_BACKLOG of them
#: waiting (a controller that published a burst without waiting for the answers lost all but the queue's last 100,
#: and two runs of the same inputs ended apart)
LOCKSTEP_BACKLOG = 10_000
INPUT_QOS = {"realtime": QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                                    reliability=ReliabilityPolicy.BEST_EFFORT),
             "lockstep": QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=LOCKSTEP_BACKLOG,
                                    reliability=ReliabilityPolicy.BEST_EFFORT)}
#: QoS per topic (default STATE_QOS)
TOPIC_QOS = {"collision_events": EVENTS_QOS, "markers": 10, "/diagnostics": 10, "/clock": 10, "/tf": 100,
             "/tf_static": LATCHED_QOS, "robot_description": LATCHED_QOS}


def for_recorded(topic: str, default: QoSProfile) -> QoSProfile:
    """The QoS to republish a recorded topic (its full name, namespace included) with: the latched ones latched, so
    that a static-transform listener or RViz's robot model (transient local) matches; `default` otherwise."""
    latched = [t for t, q in TOPIC_QOS.items() if q is LATCHED_QOS]
    return LATCHED_QOS if any(topic == t or topic.endswith("/" + t.lstrip("/")) for t in latched) else default
