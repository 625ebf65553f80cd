"""One type system for every ROS 2 message grapefmu records or publishes: the rosbags ROS 2 Jazzy typestore.

Building, serializing, writing to MCAP and reading back all go through `TYPESTORE`. This way the CDR bytes,
the ros2msg schema text and the decoder always agree. rclpy.serialization.serialize_message appends
uninitialised bytes when a message has empty arrays (e.g. JointState, Float64MultiArray), and rosbags rejects
them with "CDR message size mismatch". Bytes from `serialize` are exact, so rosbags, mcap-ros2-support and rclpy
(`Publisher.publish(bytes)` on a publisher made with the rclpy class) all accept them. No ROS installation needed.
"""
from __future__ import annotations

import operator
import os
from pathlib import Path
from functools import cache
from typing import IO, Any, Callable, Mapping

import numpy as np
from mcap.writer import CompressionType, Writer
from rosbags.interfaces import Nodetype
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from .. import __version__
from ..errors import RecordingError
from .stamps import split

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
#: grapefmu's own messages (contacts, collision events): these .msg files are the one definition, read here
#: and built for rclpy by rosidl as the grapefmu_msgs package (ros_node/interfaces/grapefmu_msgs)
MSG_DIR = Path(__file__).parent / "msg"
TYPESTORE.register({k: v for f in sorted(MSG_DIR.glob("*.msg"))
                    for k, v in get_types_from_msg(f.read_text(encoding="utf-8"), f"grapefmu_msgs/msg/{f.stem}").items()})

# rosbags keeps numeric arrays as numpy arrays and writes their raw memory as they are. A list fails, and an
# array with the wrong dtype or byte order gives wrong values without any error, so `msg` converts them.
_DTYPES = {"bool": "bool", "byte": "uint8", "char": "uint8", "octet": "uint8"}


@cache
def _dtype(desc) -> np.dtype | None:
    """numpy dtype (little endian) of an array/sequence field descriptor of a numeric base type, else None."""
    sub = desc[1][0]
    if sub[0] != Nodetype.BASE or sub[1][0] in ("string", "wstring"):
        return None
    return np.dtype(_DTYPES.get(sub[1][0], sub[1][0])).newbyteorder("<")


@cache
def _default_maker(desc) -> Callable[[], Any]:
    """A function returning a fresh default of the field (arrays and sub-messages are mutable: one each)."""
    kind, detail = desc
    if kind == Nodetype.BASE:
        name = detail[0]
        value = "" if name in ("string", "wstring") else False if name == "bool" else 0.0 if "float" in name else 0
        return lambda: value
    if kind == Nodetype.NAME:
        return lambda: msg(detail)
    size = detail[1] if kind == Nodetype.ARRAY else 0
    dt = _dtype(desc)
    if dt is not None:
        return lambda: np.zeros(size, dt)
    sub = _default_maker(detail[0])
    return lambda: [sub() for _ in range(size)]


def _numeric_array(dt: np.dtype) -> Callable[[Any], np.ndarray]:
    def coerce(value):
        if isinstance(value, (bytes, bytearray, memoryview)):  # uint8[] data such as MeshFile.data
            value = np.frombuffer(value, np.uint8)
        return np.ascontiguousarray(value, dt)
    return coerce


@cache
def _coercer(desc) -> Callable[[Any], Any]:
    """The conversion of one field's value, chosen once per field descriptor (a node builds ~10 messages a tick):
    plain Python values are accepted, dicts for sub-messages, any sequence, array or bytes for numeric arrays."""
    kind, detail = desc
    if kind == Nodetype.NAME:
        return lambda value: msg(detail, **value) if isinstance(value, dict) else value
    if kind in (Nodetype.ARRAY, Nodetype.SEQUENCE):
        if (dt := _dtype(desc)) is not None:
            return _numeric_array(dt)
        sub = _coercer(detail[0])
        return lambda value: [sub(v) for v in value]
    name = detail[0]  # scalar: store the Python type that deserialization returns, refuse 1.5 for an integer
    return str if name in ("string", "wstring") else bool if name == "bool" else \
        float if "float" in name else operator.index


@cache
def _fields(typename: str):
    """(class, [(name, coerce, default)], field names) of a message type."""
    fdefs = TYPESTORE.fielddefs[typename][1]
    return (TYPESTORE.types[typename], [(name, _coercer(desc), _default_maker(desc)) for name, desc in fdefs],
            frozenset(name for name, _ in fdefs))


def msg(typename: str, **fields) -> Any:
    """A `typename` message (e.g. "sensor_msgs/msg/JointState") from TYPESTORE. Omitted fields get their ROS
    default, because rosbags' dataclasses have no defaults. Sub-messages may be given as dicts."""
    cls, plan, names = _fields(typename)
    if not names.issuperset(fields):
        raise RecordingError(f"{typename} has no field(s) {sorted(fields.keys() - names)}")
    return cls(**{name: coerce(fields[name]) if name in fields else default() for name, coerce, default in plan})


def stamp(ns: int) -> Any:
    """builtin_interfaces/msg/Time from integer nanoseconds. Floor division keeps 0 <= nanosec < 1e9,
    also before the epoch."""
    sec, nanosec = split(ns)
    return TYPESTORE.types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec)


def header(ns: int, frame_id: str = "") -> Any:
    """std_msgs/msg/Header stamped at `ns`."""
    return TYPESTORE.types["std_msgs/msg/Header"](stamp=stamp(ns), frame_id=frame_id)


def serialize(message) -> bytes:
    """Little-endian CDR, encapsulation header included. This is the byte layout that MCAP "cdr" and rclpy's
    raw publish use."""
    return bytes(TYPESTORE.serialize_cdr(message, message.__msgtype__))


def deserialize(data: bytes | memoryview, typename: str) -> Any:
    """Decode CDR bytes into a TYPESTORE message (numeric arrays come back as numpy arrays)."""
    return TYPESTORE.deserialize_cdr(data, typename)


@cache
def schema(typename: str) -> str:
    """ros2msg text of `typename` with its dependencies appended as "====\\nMSG: pkg/Name" sections. MCAP's ros2msg
    schema encoding needs this form, and both rosbags and mcap-ros2-support parse it."""
    return TYPESTORE.generate_msgdef(typename, ros_version=2)[0]


class McapWriter:
    """MCAP writer with profile "ros2": one ros2msg schema per type, one "cdr" channel per topic, sequence numbers
    per topic starting at 1 (the MCAP spec uses 0 for "not set"), chunks compressed as mcap's Writer does by
    default (zstd), CRCs on chunks, data section and summary. Use it as a context manager. It closes the file only if it opened the file."""

    def __init__(self, output: str | os.PathLike | IO[bytes], *, compression: CompressionType = CompressionType.ZSTD,
                 chunk_size: int = 1 << 20):
        self._own = open(output, "wb") if isinstance(output, (str, os.PathLike)) else None
        # chunk CRCs (mcap's default) and the data section CRC, so that `replay --check` finds any damaged byte
        self._writer = Writer(self._own or output, chunk_size=chunk_size, compression=compression,
                              enable_data_crcs=True)
        self._writer.start(profile="ros2", library=f"grapefmu/{__version__} mcap-python")
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, tuple[int, str]] = {}
        self._seq: dict[int, int] = {}
        self._closed = False

    def _channel(self, topic: str, typename: str) -> int:
        if (ch := self._channels.get(topic)) is None:
            if (sid := self._schemas.get(typename)) is None:
                sid = self._schemas[typename] = self._writer.register_schema(typename, "ros2msg",
                                                                             schema(typename).encode())
            ch = self._channels[topic] = (self._writer.register_channel(topic, "cdr", sid), typename)
        elif ch[1] != typename:
            raise RecordingError(f"topic {topic!r} carries {ch[1]}, not {typename}")
        return ch[0]

    def write(self, topic: str, message, log_time_ns: int, publish_time_ns: int | None = None) -> None:
        """Serialize `message` with `serialize` and append it to `topic`."""
        self.write_raw(topic, message.__msgtype__, serialize(message), log_time_ns, publish_time_ns)

    def write_raw(self, topic: str, typename: str, data: bytes, log_time_ns: int,
                  publish_time_ns: int | None = None) -> None:
        """Append CDR bytes that are already serialized (they should come from `serialize`)."""
        cid = self._channel(topic, typename)
        seq = self._seq[cid] = self._seq.get(cid, 0) + 1
        self._writer.add_message(cid, int(log_time_ns), data,
                                 int(log_time_ns if publish_time_ns is None else publish_time_ns), seq)

    def add_metadata(self, name: str, data: Mapping[str, str]) -> None:
        """A metadata record, e.g. the scene and solver settings needed to re-run the simulation."""
        self._writer.add_metadata(name, {str(k): str(v) for k, v in data.items()})

    def close(self) -> None:
        """Write the summary and the footer (once). Close the file if this writer opened it."""
        if self._closed:
            return
        self._closed = True
        try:
            self._writer.finish()
        finally:
            if self._own is not None:
                self._own.close()

    def __enter__(self) -> McapWriter:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
