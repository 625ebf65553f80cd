"""Live MCAP recording of everything the node publishes and receives, through the one typestore.

Chunks are small and uncompressed and the file is flushed after every message, so a completed chunk is
on disk at once and a killed node loses at most the chunk in progress; a node stopped by SIGINT or
SIGTERM finishes the file (summary and footer) on the way out."""
from __future__ import annotations

import json
from pathlib import Path

from mcap.writer import CompressionType

from grapefmu import __version__
from grapefmu.errors import RecordingError
from grapefmu.recording.typestore import McapWriter
from grapefmu.scenefile import scene_toml

CHUNK_BYTES = 64 * 1024


class McapRecorder:
    def __init__(self, path: str | Path, metadata: dict[str, str]):
        self.path = Path(path)
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._fh = open(self.path, "wb")
        except OSError as e:  # a directory, a path under a file, no permission: the node's one-line error
            raise RecordingError(f"parameter record: cannot write {self.path}: {e.strerror or e}") from None
        self._w = McapWriter(self._fh, compression=CompressionType.NONE, chunk_size=CHUNK_BYTES)
        self._w.add_metadata("grapefmu", metadata)
        self.closed = False

    def write(self, topic: str, typename: str, data: bytes, t_ns: int) -> None:
        """Append bytes serialized by the typestore."""
        if self.closed:
            return
        self._w.write_raw(topic, typename, data, t_ns)
        self._fh.flush()  # cheap: only a chunk the writer has just completed is waiting here

    def close(self) -> None:
        if not self.closed:
            self.closed = True
            self._w.close()
            self._fh.close()


def metadata(scene, mode: str, rate_hz: float, namespace: str, integrator: str) -> dict[str, str]:
    """integrator: the pair the node's solver steps with (Solver.integrator), which a replay pins."""
    s = scene.solver
    return {"grapefmu_version": __version__, "scene_name": scene.name, "scene_toml": scene_toml(scene),
            "method": "event", "input_source": "applied", "turning": "true", "node_mode": mode, "namespace": namespace,
            "solver": json.dumps({"rtol": s.rtol, "atol": s.atol, "rate_hz": rate_hz, "integrator": integrator})}
