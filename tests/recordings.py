"""Independent readers of grapefmu's MCAP recordings: rosbags and mcap-ros2-support must decode every
message of every topic, and agree."""
from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np

from grapefmu.recording.messages import relative


def decode_everything(path: str | Path) -> Counter:
    """Decode every message with rosbags and with mcap-ros2-support (each reads the file's own schemas);
    compare the two field by field for a few fields; return messages per topic (relative to the namespace)."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    from rosbags.highlevel import AnyReader

    theirs: Counter = Counter()
    firsts = {}
    with AnyReader([Path(path)]) as reader:
        for conn, _, raw in reader.messages():
            m = reader.deserialize(raw, conn.msgtype)  # raises on a malformed message
            theirs[conn.topic] += 1
            firsts.setdefault(conn.topic, m)
    counted: Counter = Counter()
    with open(path, "rb") as fh:
        for _, channel, _, m in make_reader(fh, decoder_factories=[DecoderFactory()]).iter_decoded_messages():
            counted[channel.topic] += 1
            first = firsts[channel.topic]
            if counted[channel.topic] == 1 and hasattr(m, "header"):
                assert (m.header.stamp.sec, m.header.stamp.nanosec) == (first.header.stamp.sec,
                                                                          first.header.stamp.nanosec)
            if counted[channel.topic] == 1 and hasattr(m, "data") and not isinstance(m.data, str):
                np.testing.assert_array_equal(np.asarray(m.data, dtype=float), np.asarray(first.data, dtype=float))
    with open(path, "rb") as fh:
        summary = make_reader(fh).get_summary()
    total = sum(summary.statistics.channel_message_counts.values())
    assert sum(theirs.values()) == sum(counted.values()) == total > 0
    assert theirs == counted
    return Counter({relative(topic): n for topic, n in theirs.items()})  # "joint_states", not its full name
