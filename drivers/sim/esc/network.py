"""The emulated EtherCAT network: a line of emulated slaves serving emulated CiA-402 drives.

:class:`EmulatedNetwork` joins the slave controllers (``esc.py``), the frame processor
(``datagram.py``) and the emulated drives on the simulated arm
(:class:`drivers.sim.drive.EmulatedDrives`). Each frame that carries process data (LRD/
LWR/LRW) is answered first and then advances the drives and the plant by one tick: the
simulated time is the number of process-data frames times the bus cycle time. (No
wall-clock catch-up after a master stall, unlike the CANopen emulator: the master waits
one cycle for its frame, so the steps of a stall caught up before answering would read as
lost frames; see drivers/sim/pacing.py.) With drives, the slaves' DC clock is that
simulated time too (a start offset plus one cycle per step), so the master's DC time tells
it how far the drives' samples moved, as the SYNC0-latched samples of real drives do.

:func:`serve` binds an AF_PACKET socket for ethertype 0x88A4 to one interface (one end of a
veth pair; the master opens the other end) and runs the network until stopped. A Unix
socket (``control``) accepts one JSON object per line for fault injection and status (see
:meth:`EmulatedNetwork.control` and :class:`ControlClient`).
"""

from __future__ import annotations

import gc
import json
import math
import os
import select
import socket
import struct
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from drivers.cia402 import pdo
from drivers.sim.control_socket import (
    ControlConnections,
    open_control_socket,
    remove_own_socket,
)
from drivers.sim.drive import FAULTS, EmulatedDrives
from drivers.sim.esc import datagram
from drivers.sim.esc import registers as r
from drivers.sim.esc.description import SlaveDescription
from drivers.sim.esc.esc import Esc
from drivers.sim.pacing import answer_first
from hofto_hw.errors import UserError

ETH_P_ECAT = 0x88A4
_FAULT_KINDS = {code: kind for kind, (code, _ramp) in FAULTS.items()}


class EmulatedNetwork:
    """Slaves in line order serving the drives of ``drives`` (or bare slaves when ``None``).

    ``serve``: per drive, (slave, CiA-402 axis of that slave); default: drive i is slave i
    (one axis each). A slave serving several drives is a multi-axis device: its dictionary
    routes axis k's objects (0x6000 + 0x800·k) to drive k's
    (:class:`~drivers.sim.object_dictionary.MultiAxisDictionary`) and its process data
    reaches each drive's record. ``serve`` may cover only the first drives (a bench of
    them): the others are on no slave and never enabled."""

    def __init__(
        self,
        descriptions: Sequence[SlaveDescription],
        drives: EmulatedDrives | None,
        serve: Sequence[tuple[int, int]] | None = None,
    ) -> None:
        n = len(descriptions)
        n_drives = drives.n if drives is not None else n
        serve = [(i, 0) for i in range(n_drives)] if serve is None else list(serve)
        if len(serve) > n_drives or sorted({d for d, _k in serve}) != list(range(n)):
            raise ValueError(f"{n} slave descriptions for {n_drives} drives ({serve})")
        #: the drives of each slave, per its CiA-402 axis (None: an axis no drive emulates)
        self.records: list[list[int | None]] = [[] for _ in range(n)]
        for i, (d, k) in enumerate(serve):
            row = self.records[d]
            row.extend([None] * (k + 1 - len(row)))
            row[k] = i
        ods: list[Any] = [None] * n
        if drives is not None:
            from drivers.sim.object_dictionary import MultiAxisDictionary

            for d, row in enumerate(self.records):
                if len(row) == 1:
                    ods[d] = drives.ods[row[0]]  # type: ignore[index]
                else:
                    ods[d] = MultiAxisDictionary([drives.ods[j] if j is not None else None
                                                  for j in row])  # fmt: skip
        #: the DC local time [ns] with drives: a start offset plus one cycle per plant step
        self.dc_ns = time.monotonic_ns()
        self._cycle_ns = round(drives.dt * 1e9) if drives is not None else 0
        self._dc_clock = self._dc_time if drives is not None else None
        self.slaves = [
            Esc(d, od, i, n, dc_clock=self._dc_clock, records=self.records[i])
            for i, (d, od) in enumerate(zip(descriptions, ods, strict=True))
        ]
        self.drives = drives
        self.n = n
        #: per slave, its drives' writable objects as they power on (``restart`` restores
        #: them: start-up values and PDO configuration are lost with the power)
        self._power_on = [_power_on_values(od) for od in ods]
        #: the true arm's (t, q, qd) at every plant step until ``_trace_until`` [s of plant
        #: time] (requests ``trace`` / ``push`` with ``trace``; read by ``trace_read``): a
        #: client sees every cycle however rarely it is scheduled to ask
        self._trace: list[tuple[float, list[float], list[float]]] = []
        self._trace_until = -math.inf
        self.frames = 0
        self.process_frames = 0
        self.dropped = 0
        self.corrupted = 0
        self.malformed = 0
        self.drop_next = 0
        self.corrupt_next = 0
        self.corrupt_at = 0
        #: set by a ``stop`` request or a signal: :func:`serve` returns
        self.stopping = False
        #: the last handled frame carried process data: call :meth:`step` after replying
        self.pending_step = False
        # the slaves' outputs go straight into the drives' own RxPDO records: bytes a drive
        # does not map keep what it has (e.g. a mode written by a start-up SDO)
        self.rx = drives.rx if drives is not None else pdo.new_rx(n)
        self._rx_u8 = self.rx.view(np.uint8).reshape(-1)  # every drive's record, end to end
        self._rx_cw = self.rx["controlword"]
        if drives is not None:
            self._tx_u8 = drives.tx.view(np.uint8).reshape(-1)
        #: the slave of each drive
        self.slave_of = [d for d, _k in serve]
        self._drives_of = [[j for j in row if j is not None] for row in self.records]
        self._last_error = np.zeros(n_drives, dtype=np.uint16)
        self._changed = np.zeros(n_drives, dtype=bool)

    # ----------------------------------------------------------------- frames

    def handle(self, frame: bytearray, length: int) -> bool:
        """Process one received frame in place; False when it must not be answered.

        When the frame carried process data, :meth:`step` must be called after the reply
        is sent (``self.pending_step``).
        """
        self.frames += 1
        self.pending_step = False
        if self.drop_next > 0:
            self.drop_next -= 1
            self.dropped += 1
            return False
        cut = None
        if self.corrupt_next > 0:
            self.corrupt_next -= 1
            self.corrupted += 1
            cut = self.corrupt_at
        try:
            logical = datagram.process_frame(frame, length, self.slaves, cut)
        except ValueError:
            self.malformed += 1
            return False
        if cut is not None:
            # the damaged bytes the slaves behind the fault saw travel on to the master
            frame[datagram.ETH_HEADER + 2 + datagram.DG_HEADER] ^= 0xFF
        frame[6] |= 0x02  # port 0 marks the source MAC as locally administered, as an ESC does
        self.pending_step = logical
        return True

    def step(self) -> None:
        """One drive/plant tick with the outputs of every slave in OP (others: all zero)."""
        self.process_frames += 1
        if self.drives is None:
            return
        self.dc_ns += self._cycle_ns
        rx_u8 = self._rx_u8
        for i, s in enumerate(self.slaves):
            if not s.pull_outputs(rx_u8):
                for j in self._drives_of[i]:
                    self._rx_cw[j] = 0  # not in OP: the drive sees no enable
        self.drives.step(self.rx)
        plant = self.drives.plant
        if plant.t <= self._trace_until:
            self._trace.append((plant.t, plant.q.tolist(), plant.qd.tolist()))
        self._push_inputs()
        codes = self.drives.tx["error_code"]
        np.not_equal(codes, self._last_error, out=self._changed)
        if self._changed.any():
            for i in np.flatnonzero(self._changed):
                if i >= len(self.slave_of):
                    continue  # a drive on no slave (a bench of the first drives)
                code = int(codes[i])
                s = self.slaves[self.slave_of[i]]
                if code and s.coe is not None:
                    reg = int(self.drives.error_register[i])
                    s.queue_mailbox(s.coe.emergency(code, reg))
            np.copyto(self._last_error, codes)

    def _dc_time(self) -> int:
        return self.dc_ns

    def _push_inputs(self) -> None:
        tx_u8 = self._tx_u8
        for s in self.slaves:
            s.push_inputs(tx_u8)

    def check_watchdogs(self) -> None:
        """Run every slave's SyncManager watchdog."""
        now = time.monotonic_ns()
        for s in self.slaves:
            s.check_watchdog(now)

    # ------------------------------------------------------------ control channel

    def control(self, request: dict[str, Any]) -> dict[str, Any]:
        """Apply one control request; returns ``{"ok": True, ...}`` or ``{"ok": False,
        "error": text}``.

        Requests (``op``): ``status``; ``drop`` (count); ``corrupt`` (count, slave: first
        slave to see a damaged frame); ``silence`` (slave, on); ``drive_fault`` (slave,
        code: a 0x603F code of drivers.sim.drive.FAULTS, persistent); ``clear_drive_fault``
        (slave); ``position_jump`` (slave, offset [rad]: the reported position jumps by it
        and stays off; 0 restores); ``push`` (force [N] (3,) world frame at the tool,
        duration [s], ramp [s]: a hand on the true arm from now; answers its start ``t`` [s]
        of plant time; with ``trace`` [s] also a trace from then); ``trace`` (seconds: record
        the true arm's t, q, qd at every plant step for that long from now); ``trace_read``
        (the trace so far: t, q, qd lists, ``done`` once its time is over); ``sdo_abort`` (slave,
        index, sub (-1 = all), code; code 0 removes); ``sdo_late`` (slave, index, sub, count:
        the answers to the next ``count`` SDO requests of that object are held until the
        master's next mailbox request, then go out before its answer); ``refuse_state``
        (slave, state, code; code 0 removes); ``al_error`` (slave, code: the slave drops to
        SAFE-OP, or stays lower, with the error flag and this code);
        ``restart`` (slave: power-cycled, registers reset, INIT, no station address, its
        drives' writable objects back to their power-on values);
        ``sto``, ``brake``, ``home_switch``, ``index_phase`` (slave and the fields of
        :meth:`drivers.sim.drive.EmulatedDrives.commissioning`); ``stop``. Slaves are 0-based
        positions on the line.
        """
        op = request.get("op")
        try:
            if op == "status":
                return {"ok": True, **self.status()}
            if op == "drop":
                self.drop_next += int(request.get("count", 1))
            elif op == "corrupt":
                self.corrupt_next += int(request.get("count", 1))
                self.corrupt_at = self._slave_index(request.get("slave", 0))
            elif op == "silence":
                self.slaves[self._slave_index(request["slave"])].silent = bool(
                    request.get("on", True)
                )
            elif op == "drive_fault":
                self._drive_fault(request)
            elif op == "push":
                if self.drives is None:
                    raise ValueError("no drives on this network")
                self.drives.push_tool(
                    request["force"], float(request["duration"]), float(request.get("ramp", 0.02))
                )
                if "trace" in request:
                    self._start_trace(float(request["trace"]))
                return {"ok": True, "t": float(self.drives.plant.t)}  # the push's start [s]
            elif op == "trace":
                if self.drives is None:
                    raise ValueError("no drives on this network")
                self._start_trace(float(request["seconds"]))
                return {"ok": True, "t": float(self.drives.plant.t)}
            elif op == "trace_read":
                if self.drives is None:
                    raise ValueError("no drives on this network")
                t, q, qd = zip(*self._trace, strict=True) if self._trace else ((), (), ())
                done = self.drives.plant.t > self._trace_until
                return {"ok": True, "t": list(t), "q": list(q), "qd": list(qd), "done": done}
            elif op == "position_jump":
                if self.drives is None:
                    raise ValueError("no drives on this network")
                k = self._drive_index(request["slave"])
                self.drives.jump_position(k, float(request["offset"]))
            elif op == "clear_drive_fault":
                if self.drives is None:
                    raise ValueError("no drives on this network")
                self.drives.clear_fault(self._drive_index(request["slave"]))
            elif op == "sdo_abort":
                s = self.slaves[self._slave_index(request["slave"])]
                if s.coe is None:
                    raise ValueError("slave has no CoE server")
                key = (int(request["index"]), int(request.get("sub", -1)))
                code = int(request["code"])
                if code:
                    s.coe.forced_aborts[key] = code
                else:
                    s.coe.forced_aborts.pop(key, None)
            elif op == "sdo_late":
                s = self.slaves[self._slave_index(request["slave"])]
                if s.coe is None:
                    raise ValueError("slave has no CoE server")
                key = (int(request["index"]), int(request["sub"]))
                count = int(request.get("count", 1))
                if count < 0:
                    raise ValueError(f"count {count} < 0")
                s.late[key] = count
            elif op == "refuse_state":
                s = self.slaves[self._slave_index(request["slave"])]
                state, code = int(request["state"]), int(request["code"])
                if code:
                    s.refuse[state] = code
                else:
                    s.refuse.pop(state, None)
            elif op == "al_error":
                self.slaves[self._slave_index(request["slave"])].raise_al_error(
                    int(request["code"])
                )
            elif op == "restart":
                k = self._slave_index(request["slave"])
                old = self.slaves[k]
                for entry, value in self._power_on[k]:
                    if entry.bound is not None:
                        entry.set(value)
                    else:
                        entry.value = value
                self.slaves[k] = Esc(
                    old.desc, old.od, k, self.n, dc_clock=self._dc_clock, records=old.records
                )
            elif op == "stop":
                self.stopping = True
            elif op in EmulatedDrives.COMMISSIONING_OPS:
                if self.drives is None:
                    raise ValueError("no drives on this network")
                k = self._slave_index(request["slave"])
                return {"ok": True, **self.drives.commissioning(k, request)}
            else:
                raise ValueError(f"unknown op {op!r}")
        except (KeyError, TypeError, ValueError, IndexError) as exc:
            return {"ok": False, "error": f"{op}: {exc}"}
        return {"ok": True}

    def _start_trace(self, seconds: float) -> None:
        if not (math.isfinite(seconds) and 0.0 < seconds <= 60.0):
            raise ValueError(f"trace seconds {seconds} not in (0, 60]")
        self._trace = []
        self._trace_until = self.drives.plant.t + seconds

    def _slave_index(self, value: Any) -> int:
        i = int(value)
        if not 0 <= i < self.n:
            raise ValueError(f"slave {i} does not exist (0..{self.n - 1})")
        return i

    def _drive_index(self, value: Any) -> int:
        """A drive (joint) of the drive requests (``slave`` = the drive: one per slave, or
        one per axis of a multi-axis slave)."""
        i = int(value)
        n = self.drives.n if self.drives is not None else self.n
        if not 0 <= i < n:
            raise ValueError(f"drive {i} does not exist (0..{n - 1})")
        return i

    def _drive_fault(self, request: dict[str, Any]) -> None:
        if self.drives is None:
            raise ValueError("no drives on this network")
        code = int(request["code"])
        kind = _FAULT_KINDS.get(code)
        if kind is None:
            known = ", ".join(f"0x{c:04X}" for c in sorted(_FAULT_KINDS))
            raise ValueError(f"no injectable drive fault with code 0x{code:04X} (known: {known})")
        self.drives.inject_fault(
            self._drive_index(request["slave"]), kind, bool(request.get("persistent", False))
        )

    def status(self) -> dict[str, Any]:
        """Counters, AL states/codes per slave and the true arm state (SI)."""
        out: dict[str, Any] = {
            "frames": self.frames,
            "process_frames": self.process_frames,
            "dropped": self.dropped,
            "corrupted": self.corrupted,
            "malformed": self.malformed,
            "al_state": [s.al_state for s in self.slaves],
            "al_status_code": [s.al_status_code for s in self.slaves],
            "highest_al_state": [s.highest_state for s in self.slaves],
            "cyclic_unit_control": [s.mem[r.DC_CYCLIC_UNIT_CONTROL] for s in self.slaves],
            "station_address": [s.station_address for s in self.slaves],
            "silent": [s.silent for s in self.slaves],
        }
        if self.drives is not None:
            plant = self.drives.plant
            out.update(
                t=plant.t,
                q=plant.q.tolist(),
                qd=plant.qd.tolist(),
                tau_applied=plant.tau_applied.tolist(),
                drive_state=[int(x) for x in self.drives.state],
                error_code=[int(x) for x in self.drives.tx["error_code"]],
                **self.drives.commissioning_status(),
            )
        return out


def _power_on_values(od: Any) -> list[tuple[Any, int | bytes]]:
    """The writable objects of a slave's dictionary (every axis of a multi-axis one) with
    their values now, as the drive powers on; [] for a slave without one."""
    if od is None:
        return []
    dicts = [d for d in getattr(od, "axes", [od]) if d is not None]
    return [
        (e, e.value if e.bound is None else e.get())
        for d in dicts
        for e in d
        if e.access in ("rw", "wo")
    ]


# -------------------------------------------------------------------- the process


def open_packet_socket(iface: str) -> socket.socket:
    """AF_PACKET socket for EtherCAT frames on ``iface`` (needs root or CAP_NET_RAW)."""
    if not os.path.exists(f"/sys/class/net/{iface}"):
        raise UserError(f"network interface {iface!r} does not exist (see `ip link`)")
    try:
        sock = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(ETH_P_ECAT))
        sock.bind((iface, ETH_P_ECAT))
    except PermissionError:
        raise UserError(
            f"cannot open a raw socket on {iface!r}: needs root or CAP_NET_RAW"
        ) from None
    sock.setblocking(False)
    return sock


def serve(
    net: EmulatedNetwork,
    iface: str,
    control: str | None = None,
    duration: float | None = None,
    ready_file: str | None = None,
) -> None:
    """Answer EtherCAT frames on ``iface`` until a ``stop`` request, SIGTERM or ``duration``
    seconds. ``ready_file`` is created once the sockets are open (for test harnesses).

    Meant to run in a process of its own (``hofto-hw sim-ethercat``): it raises the calling
    process to real-time priority when allowed and pauses its garbage collector while
    serving (see :func:`_answer_first`). Control requests are served in the same loop
    without waiting for their clients (drivers.sim.control_socket.ControlConnections)."""
    sock = open_packet_socket(iface)
    srv = open_control_socket(control) if control else None
    ident = None
    clients = None
    if srv is not None and control:
        st = os.lstat(control)
        ident = (st.st_dev, st.st_ino)
        clients = ControlConnections(srv, net.control)
    buf = bytearray(2048)
    view = memoryview(buf)
    answer_first()
    if ready_file:
        with open(ready_file, "w") as f:
            f.write(str(os.getpid()))
    end = None if duration is None else time.monotonic() + duration
    next_watchdog = time.monotonic()
    try:
        while not net.stopping:
            fds: list[Any] = [sock]
            out: list[Any] = []
            if clients is not None:
                fds += clients.readers()
                out = clients.writers()
            readable, writable, _ = select.select(fds, out, [], 0.01)
            if sock in readable:
                while True:
                    try:
                        n = sock.recv_into(buf)
                    except BlockingIOError:
                        break
                    if n < 16 or struct.unpack_from("!H", buf, 12)[0] != ETH_P_ECAT:
                        continue
                    if net.handle(buf, n):
                        sock.send(view[:n])
                    if net.pending_step:
                        net.step()
            if clients is not None and (len(readable) > (sock in readable) or writable):
                if clients.ready(readable, writable):
                    gc.collect()
            now = time.monotonic()
            if now >= next_watchdog:
                net.check_watchdogs()
                next_watchdog = now + 0.01
            if end is not None and now >= end:
                break
    finally:
        gc.unfreeze()
        gc.enable()
        sock.close()
        if clients is not None:
            clients.close()
        if srv is not None:
            srv.close()
            if control and ident is not None:
                remove_own_socket(control, ident)


class ControlClient:
    """Client of the emulator's control socket: ``call(op="drop", count=1) -> dict``."""

    def __init__(self, path: str, timeout: float = 5.0) -> None:
        self.path = path
        self.timeout = timeout

    def call(self, **request: Any) -> dict[str, Any]:
        """Send one request; raises ``RuntimeError`` with the emulator's message if refused."""
        with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
            s.settimeout(self.timeout)
            s.connect(self.path)
            s.sendall(json.dumps(request).encode() + b"\n")
            data = b""
            while not data.endswith(b"\n"):
                chunk = s.recv(65536)
                if not chunk:
                    break
                data += chunk
        reply = json.loads(data.decode())
        if not reply.get("ok"):
            raise RuntimeError(f"emulator refused {request.get('op')}: {reply.get('error')}")
        return reply
