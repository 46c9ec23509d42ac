"""The arm's link frames for a log's ``/tf`` and ``/tf_static`` (runs in the writer process).

Built once from the URDF text the log carries: pinocchio's full model (every URDF joint; joints
the run does not drive stay at their neutral position), and the URDF's joint list (parent and
child link of each). For a batch of logged joint positions :meth:`ArmFrames.moving` gives each
movable joint's transform parent link -> child link, and the tool's *aligned* frame: the tool
origin with the axes of the URDF root, the frame pinocchio calls LOCAL_WORLD_ALIGNED, in which
the tool wrench estimate is expressed (hofto_hw.control.wrench). Fixed joints are constant and go
to ``/tf_static`` once per file (:meth:`ArmFrames.static`).

Transforms are (translation (3,) [m], quaternion (4,) x, y, z, w) as tf2 wants them.
"""

from __future__ import annotations

from dataclasses import dataclass
from xml.etree import ElementTree

import numpy as np
import pinocchio as pin


def aligned_frame(tool_frame: str) -> str:
    """Name of the frame at the tool origin with the root's axes (the wrench's frame)."""
    return f"{tool_frame}_aligned"


@dataclass(frozen=True)
class UrdfJoint:
    name: str
    kind: str
    parent: str
    child: str


def _urdf_joints(urdf: str) -> tuple[list[UrdfJoint], str]:
    """The URDF's joints in file order and its root link (the link no joint has as child)."""
    root = ElementTree.fromstring(urdf)
    joints = []
    for j in root.iter("joint"):
        parent, child = j.find("parent"), j.find("child")
        if parent is None or child is None:
            continue
        joints.append(UrdfJoint(j.get("name", ""), j.get("type", ""), parent.get("link", ""),
                                child.get("link", "")))  # fmt: skip
    children = {j.child for j in joints}
    links = [link.get("name", "") for link in root.iter("link")]
    roots = [name for name in links if name not in children]
    return joints, roots[0] if roots else ""


class ArmFrames:
    """Link transforms of an arm from its URDF text; ``joint_names`` (n,) are the logged
    joints in the order of the log's joint positions. ``tool_frame``: URDF frame whose aligned
    frame is added to :meth:`moving` (none when empty or not in the URDF)."""

    def __init__(self, urdf: str, joint_names: list[str], tool_frame: str = "") -> None:
        self.model = pin.buildModelFromXML(urdf)
        self.data = self.model.createData()
        m = self.model
        joints, self.root = _urdf_joints(urdf)
        for name in joint_names:
            if not m.existJointName(name):
                raise ValueError(f"joint {name!r} is not in the URDF")
        self._q0 = pin.neutral(m)
        self._iq = np.array([m.idx_qs[m.getJointId(name)] for name in joint_names], dtype=int)

        def frame(link: str) -> int:
            return m.getFrameId(link, pin.BODY) if m.existFrame(link, pin.BODY) else -1

        usable = [j for j in joints if frame(j.parent) >= 0 and frame(j.child) >= 0]
        fixed = [j for j in usable if j.kind == "fixed"]
        moving = [j for j in usable if j.kind != "fixed"]
        self._moving_ids = [(frame(j.parent), frame(j.child)) for j in moving]
        #: (parent, child) frame names of :meth:`moving`'s transforms, in order
        self.moving_pairs = [(j.parent, j.child) for j in moving]
        self._tool = -1
        if tool_frame and m.existFrame(tool_frame):
            self._tool = m.getFrameId(tool_frame)
            self.moving_pairs.append((self.root, aligned_frame(tool_frame)))
        self._fixed = fixed

    def static(self) -> list[tuple[str, str, np.ndarray, np.ndarray]]:
        """(parent, child, translation (3,), quaternion (4,)) of every fixed joint."""
        m, d = self.model, self.data
        pin.framesForwardKinematics(m, d, self._q0)
        out = []
        for j in self._fixed:
            a, b = d.oMf[m.getFrameId(j.parent, pin.BODY)], d.oMf[m.getFrameId(j.child, pin.BODY)]
            rel = a.actInv(b)
            out.append((j.parent, j.child, rel.translation.copy(), _quat(rel.rotation)))
        return out

    def moving(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """For joint positions ``q`` (K, n) [rad]: translations (K, m, 3) [m] and quaternions
        (K, m, 4) of :attr:`moving_pairs` (m of them)."""
        m, d = self.model, self.data
        k, n_pairs = q.shape[0], len(self.moving_pairs)
        trans = np.empty((k, n_pairs, 3))
        quat = np.empty((k, n_pairs, 4))
        qf = self._q0.copy()
        for i in range(k):
            qf[self._iq] = q[i]
            pin.framesForwardKinematics(m, d, qf)
            for p, (a, b) in enumerate(self._moving_ids):
                rel = d.oMf[a].actInv(d.oMf[b])
                trans[i, p] = rel.translation
                quat[i, p] = _quat(rel.rotation)
            if self._tool >= 0:
                trans[i, -1] = d.oMf[self._tool].translation
                quat[i, -1] = (0.0, 0.0, 0.0, 1.0)
        return trans, quat


def _quat(rotation: np.ndarray) -> np.ndarray:
    """(x, y, z, w) of a rotation matrix."""
    return np.asarray(pin.Quaternion(rotation).coeffs(), dtype=float).copy()
