"""The impact book of a run: one row per impact, from the pair's first touch to its separation."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .records import IMPACT, concat

__all__ = ["IMPACT", "Impacts"]


@dataclass
class Impacts:
    pair: np.ndarray              # index into model.pairs
    onset: np.ndarray             # s: δ = 0, closing
    end: np.ndarray               # s: separation (the run's end for an impact still going on)
    approach_speed: np.ndarray    # m/s, δ̇ at onset
    separation_speed: np.ndarray  # m/s, −δ̇ at separation (NaN while ongoing)
    peak_force: np.ndarray        # N, refined on the dense output
    peak_time: np.ndarray         # s
    impulse: np.ndarray           # N·s
    dissipated: np.ndarray        # J
    bruising: np.ndarray          # bool: the peak force or the dissipated energy reached its threshold
    ongoing: np.ndarray           # bool

    @property
    def duration(self) -> np.ndarray:
        return self.end - self.onset

    def __len__(self) -> int:
        return len(self.onset)

    @classmethod
    def from_records(cls, finished: np.ndarray, ongoing: np.ndarray | None = None) -> Impacts:
        """Finished and ongoing IMPACT records, ordered by onset."""
        rows, flag = finished, np.zeros(len(finished), bool)
        if ongoing is not None and len(ongoing):
            rows, flag = concat([finished, ongoing]), np.concatenate([flag, np.ones(len(ongoing), bool)])
        order = np.argsort(rows["onset"], kind="stable")
        rows, flag = rows[order], flag[order]
        return cls(rows["pair"].astype(int), rows["onset"], rows["end"], rows["approach_speed"],
                   rows["separation_speed"], rows["peak_force"], rows["peak_time"], rows["impulse"],
                   rows["dissipated"], rows["bruising"].astype(bool), flag)

    def records(self) -> np.ndarray:
        out = np.zeros(len(self), dtype=IMPACT)
        for f in IMPACT.names:
            out[f] = getattr(self, f)
        return out
