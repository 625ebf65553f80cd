"""Each pair's contact record at a run's samples, kept as the records at the first sample and the changes after.

A cluster has thousands of candidate pairs, each in contact a few times a run: recording every pair's record
at every sample (S × P records) took about 30 % of a 100-berry run, most of it the kernel zeroing the pages.
The solver logs a pair's record at the first sample where it differs from the one logged before
(solver/loop.py record_grid); the dense array is built when it is asked for (Run.contacts).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..physics.forces import CONTACT

#: from sample `sample` on, pair `pair` has this CONTACT record (mode, onset speed, smooth flag)
CHANGE = np.dtype([("sample", "i8"), ("pair", "i8"), ("mode", "i8"), ("v_onset", "f8"), ("smooth", "?")])


@dataclass(frozen=True)
class ContactLog:
    start: np.ndarray    # (P,) CONTACT at the first sample
    changes: np.ndarray  # (K,) CHANGE, in order of sample (a pair's later change after its earlier one)

    @classmethod
    def of(cls, dense: np.ndarray) -> ContactLog:
        """The log of a dense (S, P) CONTACT array."""
        dense = np.ascontiguousarray(dense)
        if len(dense) == 0:
            return cls(np.zeros(dense.shape[1], CONTACT), np.zeros(0, CHANGE))
        s, p = np.nonzero(dense[1:] != dense[:-1])
        rows = np.zeros(len(s), CHANGE)
        rows["sample"], rows["pair"] = s + 1, p
        for f in CONTACT.names:
            rows[f] = dense[f][s + 1, p]
        return cls(dense[0].copy(), rows)

    def dense(self, n_samples: int) -> np.ndarray:
        """(n_samples, P) CONTACT: each pair's record at each sample."""
        out = np.empty((n_samples, len(self.start)), CONTACT)
        pairs, latest = self._latest(n_samples)
        for f in CONTACT.names:
            out[f] = self.start[f]
            out[f][:, pairs] = np.where(latest < 0, self.start[f][pairs], self.changes[f][latest])
        return out

    def mode(self, n_samples: int) -> np.ndarray:
        """(n_samples, P) int8: each pair's mode at each sample (0 apart, 1 loaded, 2 overlapping but unloaded)."""
        out = np.empty((n_samples, len(self.start)), np.int8)
        out[:] = self.start["mode"]
        pairs, latest = self._latest(n_samples)
        out[:, pairs] = np.where(latest < 0, self.start["mode"][pairs], self.changes["mode"][latest])
        return out

    def _latest(self, n_samples: int) -> tuple[np.ndarray, np.ndarray]:
        """The pairs that change, and (n_samples, their count) the index of the change each one's record at each
        sample comes from (−1: the start). Changes are in time order, so the latest so far is the largest so far."""
        pairs, column = np.unique(self.changes["pair"], return_inverse=True)
        at = np.full((n_samples, len(pairs)), -1, np.intp)
        np.maximum.at(at, (self.changes["sample"], column), np.arange(len(self.changes)))
        return pairs, np.maximum.accumulate(at, axis=0)
