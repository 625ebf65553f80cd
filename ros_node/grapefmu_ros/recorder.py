"""Live MCAP recording of everything the node publishes and receives.

The writer keeps the chunk in progress in memory and the file is flushed after every message, so a
completed chunk is on disk at once and a killed node loses at most the chunk in progress; a node
stopped by SIGINT or SIGTERM finishes the file (summary and footer) on the way out."""
from __future__ import annotations

import json
from pathlib import Path

from mcap.writer import CompressionType, Writer
from rclpy.serialization import serialize_message

from grapefmu import __version__

from .msgdefs import full_definition

CHUNK_BYTES = 64 * 1024


def ros_type_name(msg) -> str:
    mod = type(msg).__module__.split(".")[0]
    return f"{mod}/msg/{type(msg).__name__}"


class McapRecorder:
    def __init__(self, path: str | Path, metadata: dict[str, str]):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._fh = open(self.path, "wb")
        self._w = Writer(self._fh, chunk_size=CHUNK_BYTES, compression=CompressionType.NONE)
        self._w.start(profile="ros2", library=f"grapefmu {__version__}")
        self._w.add_metadata("grapefmu", metadata)
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._seq: dict[str, int] = {}
        self.closed = False

    def write(self, topic: str, msg, t_ns: int) -> None:
        if self.closed:
            return
        dtype = ros_type_name(msg)
        if dtype not in self._schemas:
            self._schemas[dtype] = self._w.register_schema(dtype, "ros2msg", full_definition(dtype).encode())
        if topic not in self._channels:
            self._channels[topic] = self._w.register_channel(topic, "cdr", self._schemas[dtype])
        seq = self._seq[topic] = self._seq.get(topic, -1) + 1
        self._w.add_message(self._channels[topic], log_time=t_ns, data=serialize_message(msg), publish_time=t_ns,
                            sequence=seq)
        self._fh.flush()  # cheap: only a chunk the writer has just completed is waiting here

    def close(self) -> None:
        if not self.closed:
            self.closed = True
            self._w.finish()
            self._fh.close()


def metadata(scene, mode: str, rate_hz: float) -> dict[str, str]:
    s = scene.solver
    return {"grapefmu_version": __version__, "scene_name": scene.name, "scene_toml": scene.source,
            "method": "event", "input_source": "applied", "node_mode": mode,
            "solver": json.dumps({"rtol": s.rtol, "atol": s.atol, "rate_hz": rate_hz})}
