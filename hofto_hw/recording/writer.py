"""Write joint-state MCAP logs (offline or from a thread outside the tick).

Not for the tick itself: encoding a message allocates. The real-time logger copies into a
ring buffer in the tick and feeds this writer from another thread.
"""

from __future__ import annotations

from pathlib import Path
from types import TracebackType
from typing import IO, Any

import numpy as np
from mcap_ros2.writer import Writer as Ros2Writer
from numpy.typing import NDArray

from hofto_hw.errors import UserError
from hofto_hw.recording.schemas import (
    JOINT_STATE_MSGDEF,
    JOINT_STATE_TOPIC,
    JOINT_STATE_TYPE,
    METADATA_NAME,
)


class JointStateWriter:
    """An MCAP file of ``sensor_msgs/msg/JointState`` messages on one topic.

    Use as a context manager or call :meth:`close`; the file is valid only once closed.
    """

    def __init__(
        self,
        path: str | Path,
        joint_names: list[str],
        *,
        topic: str = JOINT_STATE_TOPIC,
        metadata: dict[str, str] | None = None,
    ) -> None:
        self.path = Path(path)
        self.joint_names = list(joint_names)
        self.topic = topic
        try:
            self._file: IO[bytes] = self.path.open("wb")
        except OSError as exc:
            raise UserError(f"{self.path}: cannot write log: {exc.strerror}") from None
        self._writer = Ros2Writer(self._file)
        self._schema = self._writer.register_msgdef(JOINT_STATE_TYPE, JOINT_STATE_MSGDEF)
        meta = {"joint_names": ",".join(self.joint_names), "topic": topic}
        meta.update(metadata or {})
        self._writer.add_metadata(METADATA_NAME, meta)
        self._seq = 0

    def write(
        self, t: float, q: NDArray[np.float64], qd: NDArray[np.float64], tau: NDArray[np.float64]
    ) -> None:
        """Append one joint state at time ``t`` [s]; q [rad], qd [rad/s], tau [N·m], (n,)."""
        ns = round(t * 1e9)
        msg: dict[str, Any] = {
            "header": {
                "stamp": {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000},
                "frame_id": "",
            },
            "name": self.joint_names,
            "position": [float(v) for v in q],
            "velocity": [float(v) for v in qd],
            "effort": [float(v) for v in tau],
        }
        self._writer.write_message(
            self.topic, self._schema, msg, log_time=ns, publish_time=ns, sequence=self._seq
        )
        self._seq += 1

    def close(self) -> None:
        """Finish the MCAP summary and close the file."""
        if not self._file.closed:
            self._writer.finish()
            self._file.close()

    def __enter__(self) -> JointStateWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


def write_joint_states(
    path: str | Path,
    t: NDArray[np.float64],
    q: NDArray[np.float64],
    qd: NDArray[np.float64],
    tau: NDArray[np.float64],
    joint_names: list[str] | None = None,
    metadata: dict[str, str] | None = None,
) -> Path:
    """Write a whole series: ``t`` (N,) [s], ``q``/``qd``/``tau`` (N, n). Returns the path."""
    n = q.shape[1]
    names = joint_names or [f"joint_{j + 1}" for j in range(n)]
    with JointStateWriter(path, names, metadata=metadata) as w:
        for k in range(t.shape[0]):
            w.write(float(t[k]), q[k], qd[k], tau[k])
    return Path(path)
