"""The monitor's per-tick state: preallocated arrays that both implementations (numpy
reference, compiled kernel) read and write in place.

Shapes, with L levels, k observer rows and n joints (row k is the fused ``mean`` row):

- ``feat`` (6, n): qd_prev [rad/s], a (low-passed acceleration) [rad/s²], moving, reversal,
  still (indicators in [0, 1]), qd_ok (qd with non-finite entries replaced by the last
  finite ones) [rad/s];
- ``sst`` (3,): started (0/1), phase_left [s], accel_phase (0/1);
- ``lev`` (L, 4, k + 1, n): threshold [N·m] (row k unused), ratio |tau_ext|/threshold (row k:
  the mean over the deciding rows), time above [s], time below release_ratio [s];
- ``joints`` (L, k + 1, n) bool: tripped (debounced, with hysteresis) per level/row/joint;
- ``bad`` (k + 3, n) bool: rows 0..k-1 tau_ext non-finite, row k a deciding row's tau_ext
  non-finite (the fused row's), row k + 1 qd non-finite, row k + 2 either (``nonfinite``);
- ``row_hit`` (L, k + 1) bool: a row has a tripped joint;
- ``level_joints`` (L, n) bool: the decision's joints per level; ``hits`` (L + 1,) bool: each
  level's decision, then ``fault_nonfinite``;
- ``first_tick`` (k,) int64: the tick each row first tripped the collision level (-1: never).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

# feat rows
F_QD_PREV, F_ACCEL, F_MOVING, F_REVERSAL, F_STILL, F_QD_OK = range(6)
# sst entries
ST_STARTED, ST_PHASE_LEFT, ST_ACCEL_PHASE = range(3)
# lev planes
L_THR, L_RATIO, L_ABOVE, L_BELOW = range(4)
# a tick's flags (CollisionLevels.update's answer): the collision level decided, the contact
# level decided (only with two levels), an estimate or the velocity was non-finite
COLLIDED, CONTACT, NONFINITE = 1, 2, 4


def flags_of(hits: np.ndarray) -> int:
    """The flags of ``hits`` (L + 1,) bool (the compiled kernel computes the same)."""
    L = hits.shape[0] - 1
    flags = COLLIDED if hits[L - 1] else 0
    if L > 1 and hits[0]:
        flags |= CONTACT
    if hits[L]:
        flags |= NONFINITE
    return flags


class MonitorState:
    """See the module docstring. Every float array (with a copy of the constant ``par`` (L, 6,
    k, n) and ``scal``) is a view of one buffer ``fbuf``, every bool array (with a copy of
    ``deciding`` (k,)) a view of ``bbuf``: the compiled kernel then takes two arrays instead of
    fifteen (numba's per-argument call cost dominates a tick this small)."""

    def __init__(
        self,
        levels: int,
        k: int,
        n: int,
        n_scal: int = 12,
        hot: Mapping[str, np.ndarray] | None = None,
    ) -> None:
        fshapes, bshapes = self._shapes(levels, k, n, n_scal)
        #: the packed numbers as one record (the tick's compiled call takes it and bbuf as its
        #: arguments: numba has no boolean fields); fbuf and first_tick are its fields
        f = self.hot_fields(levels, k, n, n_scal)
        if hot is None:
            self.record, self.bbuf = np.zeros(1, f["record"]), np.zeros(f["bbuf"].shape, bool)
        else:
            self.record, self.bbuf = hot["record"], hot["bbuf"]
        self.fbuf = self.record["fbuf"][0]
        for buf, shapes in ((self.fbuf, fshapes), (self.bbuf, bshapes)):
            at = 0
            for name, shape in shapes.items():
                size = int(np.prod(shape))
                setattr(self, name, buf[at : at + size].reshape(shape))
                at += size
        self.first_tick = self.record["first_tick"][0]
        self.first_tick.fill(-1)

    @staticmethod
    def _shapes(L: int, k: int, n: int, n_scal: int) -> tuple[dict, dict]:
        """The float and bool arrays' shapes, in their buffers' order."""
        fshapes = {
            "par": (L, 6, k, n),
            "scal": (n_scal,),
            "feat": (6, n),
            "sst": (3,),
            "lev": (L, 4, k + 1, n),
        }
        bshapes = {
            "deciding": (k,),
            "joints": (L, k + 1, n),
            "bad": (k + 3, n),
            "row_hit": (L, k + 1),
            "level_joints": (L, n),
            "hits": (L + 1,),
        }
        return fshapes, bshapes

    @staticmethod
    def hot_fields(levels: int, k: int, n: int, n_scal: int = 12) -> dict[str, np.dtype]:
        """``record`` (fbuf, first_tick) and ``bbuf`` as fields of a caller-owned record
        (``hot=``: the constructor takes them, zeroed, instead of allocating)."""
        fs, bs = MonitorState._shapes(levels, k, n, n_scal)
        nf = sum(int(np.prod(v)) for v in fs.values())
        nb = sum(int(np.prod(v)) for v in bs.values())
        rec = np.dtype([("fbuf", np.float64, (nf,)), ("first_tick", np.int64, (k,))])
        return {"record": rec, "bbuf": np.dtype((np.bool_, (nb,)))}

    def reset(self, par: np.ndarray, qd: np.ndarray | None, v_rev: float) -> None:
        """Forget everything; thresholds back to the nominal bases; a finite ``qd`` (n,)
        [rad/s] seeds the acceleration estimate and the moving indicator."""
        self.feat.fill(0.0)
        self.sst.fill(0.0)
        self.lev.fill(0.0)
        k = par.shape[2]
        np.copyto(self.lev[:, L_THR, :k], par[:, 0])
        self.joints.fill(False)
        self.bad.fill(False)
        self.row_hit.fill(False)
        self.level_joints.fill(False)
        self.hits.fill(False)
        self.first_tick.fill(-1)
        if qd is not None and np.all(np.isfinite(qd)):  # a non-finite seed is no seed
            self.feat[F_QD_PREV] = qd
            self.feat[F_MOVING] = np.abs(qd) > v_rev
            self.sst[ST_STARTED] = 1.0
