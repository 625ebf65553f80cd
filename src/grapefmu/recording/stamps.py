"""Time stamps as integer nanoseconds, converted to seconds the same way everywhere, so that a replay
computes bit for bit the same intervals the recorded run integrated."""
from __future__ import annotations


def to_ns(t: float) -> int:
    return int(round(t * 1e9))


def seconds(ns: int) -> float:
    return ns / 1e9


def split(ns: int) -> tuple[int, int]:
    """(sec, nanosec) of a ROS time stamp, 0 ≤ nanosec < 1e9 (also before the epoch)."""
    return divmod(int(ns), 1_000_000_000)


def stamp_seconds(sec: int, nanosec: int) -> float:
    return seconds(sec * 1_000_000_000 + nanosec)
