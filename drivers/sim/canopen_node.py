"""Emulated CANopen CiA-402 drives: :class:`~drivers.sim.drive.EmulatedDrives` as CANopen
nodes on a python-can bus.

One node per drive (node ids in drive order), or per device with multi-axis drives
(``serve``: per drive, (node, CiA-402 axis of that node)): such a node serves its axes'
dictionaries through one :class:`~drivers.sim.object_dictionary.MultiAxisDictionary` (axis
k's objects at 0x6000 + 0x800·k), its PDOs carry every axis's objects into that axis's drive
record, and it has one NMT state, one heartbeat, one SDO server and one EMCY COB-ID; an
EMCY of axis k carries k in the byte its profile names (``canopen.emcy_axis_byte``). Each
node serves the drive's own
:class:`~drivers.sim.object_dictionary.ObjectDictionary` (the one SimBus and the EtherCAT
emulator serve) extended with the CiA 301 communication objects (:func:`add_canopen_objects`):
SYNC/EMCY COB-IDs, heartbeat producer 0x1017, RPDO/TPDO communication 0x1400/0x1401,
0x1800/0x1801 and mapping 0x1600/0x1601, 0x1A00/0x1A01 with the layout of
:mod:`drivers.canopen.layout` as default. :func:`eds_text` writes the same dictionary as an
EDS file (configs/canopen/emulated_drive.eds).

Per node: NMT slave (boot-up, pre-operational, operational, stopped, reset communication),
SDO server (expedited and segmented upload/download, toggle check, aborts with the
dictionary's CiA 301 codes; block transfer is answered with 0x05040001), synchronous RPDOs
latched until the SYNC, TPDOs sent on every SYNC (transmission type n: every n-th SYNC),
heartbeat producer, EMCY when the drive's 0x603F changes (code 0 = error reset).

Each SYNC first sends the TPDOs (inputs sampled at the SYNC, CiA 301 synchronous), then
applies the RPDOs latched before it and steps the drives and the plant by one tick: the
answer does not wait for the plant step, and a command is seen in the TPDOs of the next
SYNC. Simulated time is the number of SYNCs times the plant tick (see drivers/sim/pacing.py
for why a wall-clock catch-up after a master stall was tried and left out). Fault injection
(:meth:`CanopenDrives.control`): silent node, heartbeat stopped, EMCY with a code, SDO abort
with a code, late or missing TPDOs, wrong identity, bus-off.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from drivers.canopen import layout
from drivers.cia402.pdo import RXPDO_DTYPE, RXPDO_SIZE, TXPDO_DTYPE, TXPDO_SIZE, mapping_value
from drivers.sim.drive import FAULTS, EmulatedDrives
from drivers.sim.object_dictionary import KINDS, ObjectDictionary, OdEntry, SdoAbort

_FAULT_KINDS = {code: kind for kind, (code, _ramp) in FAULTS.items()}
ABORT_COMMAND = 0x05040001
ABORT_TOGGLE = 0x05030000
CODE_BUS_OFF_RECOVERED = 0x8140
CODE_PDO_LENGTH = 0x8210


def pdo_objects(profile: Any) -> list[tuple[str, int, int, int, int, bool]]:
    """(name, communication index, mapping index, COB-ID base, transmission type, enabled)
    of every PDO of a drive: its profile's (CANopen section), else the layout of
    :mod:`drivers.canopen.layout`."""
    if profile is None:
        return [
            (f"{kind}{k + 1}", p.comm_index, p.map_index, p.cob_base, layout.SYNC_EVERY, True)
            for pdos, kind in ((layout.RPDOS, "RPDO"), (layout.TPDOS, "TPDO"))
            for k, p in enumerate(pdos)
        ]
    out = []
    for pdos, comms, base, kind in (
        (profile.rx_pdos, profile.canopen.rpdo, 0x1400, "RPDO"),
        (profile.tx_pdos, profile.canopen.tpdo, 0x1800, "TPDO"),
    ):
        for p, c in zip(pdos, comms, strict=True):
            k = p.index & 0x1FF
            out.append(
                (
                    f"{kind}{k + 1}",
                    base + k,
                    p.index,
                    c.cob_id_base,
                    c.transmission_type,
                    c.enabled_by_default,
                )
            )
    return out


def add_canopen_objects(od: ObjectDictionary, node_id: int, profile: Any = None) -> None:
    """Add the CiA 301 communication objects of node ``node_id`` to a drive dictionary and
    set the PDO mappings to :mod:`drivers.canopen.layout`'s defaults; for a drive that
    impersonates ``profile`` (its mapping objects already in ``od``): the communication
    objects of its PDOs, disabled (COB-ID bit 31) where its file says so."""
    od.max_pdo_bits = 64
    od.mapping_needs_invalid_pdo = True  # CiA 301: remap only a PDO made invalid
    if profile is not None:
        od.add_var(0x1005, "COB-ID SYNC", "u32", "rw", layout.SYNC_COB_ID)
        od.add_var(0x1014, "COB-ID EMCY", "u32", "ro", layout.EMCY_BASE + node_id)
        od.add_var(0x1017, "producer heartbeat time", "u16", "rw", 0)
        for name, comm, _map, base, ttype, enabled in pdo_objects(profile):
            cob = base + node_id | (0 if enabled else layout.COB_ID_INVALID)
            od.add_record(
                comm,
                f"{name} communication parameter",
                [
                    OdEntry(comm, 1, "COB-ID used by PDO", "u32", "rw", cob),
                    OdEntry(comm, 2, "transmission type", "u8", "rw", ttype),
                ],
            )
        return
    od.add_var(0x1005, "COB-ID SYNC", "u32", "rw", layout.SYNC_COB_ID)
    od.add_var(0x1014, "COB-ID EMCY", "u32", "ro", layout.EMCY_BASE + node_id)
    od.add_var(0x1017, "producer heartbeat time", "u16", "rw", 0)
    for pdos, kind in ((layout.RPDOS, "RPDO"), (layout.TPDOS, "TPDO")):
        for k, p in enumerate(pdos):
            subs = [
                OdEntry(p.comm_index, 1, "COB-ID used by PDO", "u32", "rw", p.cob_base + node_id),
                OdEntry(p.comm_index, 2, "transmission type", "u8", "rw", layout.SYNC_EVERY),
            ]
            od.add_record(p.comm_index, f"{kind}{k + 1} communication parameter", subs)
            if (p.map_index, 0) not in od:
                od.add(
                    OdEntry(p.map_index, 0, "number of mapped objects", "u8", "rw", 0),
                    f"{kind}{k + 1} mapping parameter",
                )
                for s in range(1, 9):
                    od.add(OdEntry(p.map_index, s, f"mapped object {s}", "u32", "rw", 0))
            for s in range(1, 17):
                if (p.map_index, s) in od:
                    od.set(p.map_index, s, 0)
            for s, e in enumerate(p.entries, start=1):
                od.set(p.map_index, s, mapping_value(e))
            od.set(p.map_index, 0, len(p.entries))


def _indices(
    entries: Any, dtype: np.dtype, records: Sequence[int | None], size: int
) -> tuple[np.ndarray, np.ndarray]:
    """(payload byte, flat record byte) index arrays of the known objects of a mapping;
    ``records``: per CiA-402 axis k of the node (objects at 0x6000 + 0x800·k), the drive
    whose record it is (None: no drive emulates it). Padding, vendor objects and objects of
    an axis without a drive travel as bytes nothing reads (zero when sent)."""
    from drivers.cia402.pdo import OBJECT_FIELDS
    from drivers.cia402.wire import split_object

    payload: list[int] = []
    record: list[int] = []
    off = 0
    for e in entries:
        n = e.bit_length // 8
        found = split_object(e.index, e.subindex) if e.index else None
        rec = records[found[1]] if found is not None and found[1] < len(records) else None
        field = OBJECT_FIELDS[(found[0], e.subindex)] if found is not None else None
        if rec is not None and field in (dtype.names or ()):
            ro = rec * size + dtype.fields[field][1]
            payload.extend(range(off, off + n))
            record.extend(range(ro, ro + n))
        off += n
    return np.array(payload, dtype=np.intp), np.array(record, dtype=np.intp)


class CanopenDrives:
    """Emulated CiA-402 drives as CANopen nodes on ``bus`` (a python-can bus object).

    Call :meth:`poll` in a loop (or :meth:`start` a thread). ``serve``: per drive, (node
    position, CiA-402 axis of that node); default drive i is node i's only axis. ``node_ids``
    one per node, default 1..n.
    """

    def __init__(
        self,
        drives: EmulatedDrives,
        bus: Any,
        node_ids: Sequence[int] | None = None,
        serve: Sequence[tuple[int, int]] | None = None,
    ) -> None:
        import can

        from drivers.sim.object_dictionary import MultiAxisDictionary

        self._can = can
        self.drives = drives
        self.bus = bus
        serve = [(i, 0) for i in range(drives.n)] if serve is None else list(serve)
        n = max(d for d, _k in serve) + 1
        if len(serve) != drives.n or sorted({d for d, _k in serve}) != list(range(n)):
            raise ValueError(f"serve {serve} does not number {drives.n} drives' nodes from 0")
        #: number of nodes
        self.n = n
        #: the drives of each node, per its CiA-402 axis (None: an axis no drive emulates)
        self.records: list[list[int | None]] = [[] for _ in range(n)]
        for i, (d, k) in enumerate(serve):
            row = self.records[d]
            row.extend([None] * (k + 1 - len(row)))
            row[k] = i
        #: the node of each drive
        self.node_of = [d for d, _k in serve]
        self.axis_of = [k for _d, k in serve]
        self.node_ids = list(node_ids) if node_ids is not None else list(range(1, n + 1))
        if len(self.node_ids) != n:
            raise ValueError(f"{len(self.node_ids)} node ids for {n} nodes")
        heads = [row[0] for row in self.records]
        if any(h is None for h in heads):
            raise ValueError("axis 0 of every node needs a drive")
        #: the dictionary of axis 0's drive: the node's communication objects live there
        self._od0 = [drives.ods[h] for h in heads]  # type: ignore[index]
        #: what the node serves by SDO (every axis's CiA-402 objects on a multi-axis node)
        self.ods: list[Any] = [
            drives.ods[row[0]]  # type: ignore[index]
            if len(row) == 1
            else MultiAxisDictionary([drives.ods[j] if j is not None else None for j in row])
            for row in self.records
        ]
        all_profiles = list(getattr(drives, "profiles", [None] * drives.n))
        self.profiles = [all_profiles[h] for h in heads]  # type: ignore[index]
        for od, nid, prof in zip(self._od0, self.node_ids, self.profiles, strict=True):
            add_canopen_objects(od, nid, prof)
        #: per node: the EMCY byte carrying the axis (None: the EMCY does not say)
        self._emcy_axis_byte = [
            p.canopen.emcy_axis_byte if p is not None and p.canopen is not None else None
            for p in self.profiles
        ]
        self._pdo_objects = [pdo_objects(p) for p in self.profiles]
        self.nmt = np.full(n, layout.NMT_PRE_OPERATIONAL, dtype=np.uint8)
        self.silent = np.zeros(n, dtype=bool)
        self.no_heartbeat = np.zeros(n, dtype=bool)
        self.bus_off = np.zeros(n, dtype=bool)
        self.tpdo_drop = np.zeros(n, dtype=np.int64)
        self.tpdo_late = np.zeros(n, dtype=np.int64)
        self.tpdo_delay = np.zeros(n)
        self.forced_aborts: dict[tuple[int, int, int], int] = {}
        self._identity_saved: dict[tuple[int, int], int] = {}
        self.syncs = 0
        self.frames = 0
        self.stopping = False
        self.lock = threading.RLock()
        self._thread: threading.Thread | None = None
        self._rx = drives.rx.copy()
        self._rx_flat = self._rx.view(np.uint8).reshape(-1)
        self._drive_rx_flat = drives.rx.view(np.uint8).reshape(-1)
        #: RxPDO record bytes no RPDO carries: the drive's own values (e.g. an SDO-set mode)
        self._unmapped = np.ones(self._rx_flat.size, dtype=bool)
        self._tx_flat = drives.tx.view(np.uint8).reshape(-1)
        self._got_rpdo = False
        self._last_error = np.zeros(drives.n, dtype=np.uint16)
        from drivers.sim.plant_trace import PlantTrace

        #: the true arm at every plant step for a while (requests ``trace`` / ``push``)
        self.trace = PlantTrace(drives.plant)
        self._hb_next = np.zeros(n)
        self._sdo: list[dict[str, Any]] = [{} for _ in range(n)]
        self._delayed: list[tuple[float, Any]] = []
        self._queued_until = np.zeros(n)  # [s] due time of each node's last delayed frame
        self._rpdo: dict[int, tuple[int, tuple[np.ndarray, np.ndarray], int]] = {}
        self._tpdo: list[list[tuple[Any, Any, np.ndarray, int]]] = [[] for _ in range(n)]
        self._by_sdo = {layout.SDO_RX_BASE + nid: i for i, nid in enumerate(self.node_ids)}

    @classmethod
    def for_bus(cls, drives: EmulatedDrives, bus: Any, bus_config: Any) -> CanopenDrives:
        """The nodes of a :class:`hofto_hw.config.drives.BusConfig`: one per device
        (``bus.drives[i].device`` / ``device_axis``), node ids ``bus.canopen.node_ids`` or
        1..n."""
        from hofto_hw.config.drives import device_map

        opts = getattr(bus_config, "canopen", None)
        ids = opts.node_ids if opts is not None and opts.node_ids else None
        return cls(drives, bus, ids, device_map(bus_config.drives))

    # ------------------------------------------------------------------ sending

    def _send(self, cob: int, data: bytes | bytearray) -> None:
        msg = self._can.Message(arbitration_id=cob, data=data, is_extended_id=False)
        try:
            self.bus.send(msg)
        except self._can.CanError:
            pass  # a real node's frame is lost the same way; the master sees a timeout

    def _talks(self, i: int) -> bool:
        return not (self.silent[i] or self.bus_off[i])

    def _emcy(self, i: int, code: int, register: int, axis: int = 0) -> None:
        """EMCY of node ``i`` (of its CiA-402 ``axis``, in the profile's byte if it names
        one)."""
        if self._talks(i):
            data = bytearray([code & 0xFF, code >> 8, register, 0, 0, 0, 0, 0])
            where = self._emcy_axis_byte[i]
            if where is not None:
                data[where] = axis
            self._send(layout.EMCY_BASE + self.node_ids[i], data)

    # ---------------------------------------------------------------------- NMT

    def _boot(self, i: int) -> None:
        self.nmt[i] = layout.NMT_PRE_OPERATIONAL
        self.ods[i].pdo_locked = False
        self._od0[i].set(0x1017, 0, 0)
        self._sdo[i].clear()
        if self._talks(i):
            self._send(layout.HEARTBEAT_BASE + self.node_ids[i], b"\x00")

    def _nmt(self, data: bytes) -> None:
        if len(data) < 2:
            return
        cmd, target = data[0], data[1]
        for i, nid in enumerate(self.node_ids):
            if target not in (0, nid) or self.bus_off[i]:
                continue
            if cmd == layout.NMT_START:
                self.nmt[i] = layout.NMT_OPERATIONAL
                self.ods[i].pdo_locked = True
            elif cmd == layout.NMT_STOP:
                self.nmt[i] = layout.NMT_STOPPED
                self.ods[i].pdo_locked = False
            elif cmd == layout.NMT_ENTER_PRE_OP:
                self.nmt[i] = layout.NMT_PRE_OPERATIONAL
                self.ods[i].pdo_locked = False
            elif cmd in (layout.NMT_RESET_COMM, layout.NMT_RESET_NODE):
                self._boot(i)
        self._build_pdos()

    def _build_pdos(self) -> None:
        """Copy plans from the PDO objects of every operational node (what the master wrote)."""
        self._rpdo.clear()
        self._unmapped.fill(True)
        for i in range(self.n):
            self._tpdo[i] = []
            if self.nmt[i] != layout.NMT_OPERATIONAL:
                continue
            od = self.ods[i]
            for _name, comm, map_index, _base, _tt, _en in self._pdo_objects[i]:
                cob = od.get(comm, 1)
                if cob & layout.COB_ID_INVALID:
                    continue
                entries = od.mapping(map_index)
                size = sum(e.bit_length for e in entries) // 8
                if map_index < 0x1A00:
                    idx = _indices(entries, RXPDO_DTYPE, self.records[i], RXPDO_SIZE)
                    self._rpdo[cob & 0x7FF] = (i, idx, size)
                    self._unmapped[idx[1]] = False
                else:
                    idx = _indices(entries, TXPDO_DTYPE, self.records[i], TXPDO_SIZE)
                    every = max(1, min(240, od.get(comm, 2)))
                    payload = np.zeros(size, dtype=np.uint8)
                    self._tpdo[i].append((cob & 0x7FF, idx, payload, every))

    # --------------------------------------------------------------------- SYNC

    def _sync(self) -> None:
        self.syncs += 1
        now = time.monotonic()
        self._send_due(now)
        for i in range(self.n):
            if self.nmt[i] != layout.NMT_OPERATIONAL or not self._talks(i):
                continue
            if self.tpdo_drop[i] > 0:
                self.tpdo_drop[i] -= 1
                continue
            # a node sends its frames in order: after a late spell, the frames of the later
            # SYNCs queue behind the delayed ones (the backlog comes out in one burst)
            behind = self._queued_until[i] > now
            for cob, idx, payload, every in self._tpdo[i]:
                if self.syncs % every:
                    continue
                payload[idx[0]] = self._tx_flat[idx[1]]
                if self.tpdo_late[i] > 0 or behind:
                    msg = self._can.Message(
                        arbitration_id=cob, data=payload.tobytes(), is_extended_id=False
                    )
                    due = now + float(self.tpdo_delay[i]) if self.tpdo_late[i] > 0 else now
                    due = max(due, float(self._queued_until[i]))
                    self._queued_until[i] = due
                    self._delayed.append((due, msg))
                else:
                    self._send(cob, payload.tobytes())
            if self.tpdo_late[i] > 0:
                self.tpdo_late[i] -= 1
        # TPDOs are sampled at the SYNC and sent first; then the RPDOs latched before this
        # SYNC take effect for one tick (the plant step does not delay the answer).
        if self._got_rpdo:
            np.copyto(self._rx_flat, self._drive_rx_flat, where=self._unmapped)
        self.drives.step(self._rx if self._got_rpdo else None)
        self.trace.sample()
        self._got_rpdo = False
        err = self.drives.tx["error_code"]
        if (err != self._last_error).any():
            for j in np.flatnonzero(err != self._last_error):
                i = self.node_of[j]
                self._emcy(i, int(err[j]), int(self.drives.error_register[j]), self.axis_of[j])
            np.copyto(self._last_error, err)

    # ---------------------------------------------------------------------- SDO

    def _abort(self, i: int, index: int, sub: int, code: int) -> None:
        self._sdo[i].clear()
        data = bytes([0x80, index & 0xFF, index >> 8, sub]) + code.to_bytes(4, "little")
        self._send(layout.SDO_TX_BASE + self.node_ids[i], data)

    def _sdo_request(self, i: int, data: bytes) -> None:
        if len(data) != 8 or self.nmt[i] == layout.NMT_STOPPED:
            return
        cmd = data[0]
        ccs = cmd >> 5
        od, sess = self.ods[i], self._sdo[i]
        reply = layout.SDO_TX_BASE + self.node_ids[i]
        if ccs == 4:  # abort from the client
            sess.clear()
            return
        if ccs in (1, 2):
            index, sub = data[1] | (data[2] << 8), data[3]
        else:
            index, sub = sess.get("index", 0), sess.get("sub", 0)
        forced = self.forced_aborts.get((i, index, sub)) or self.forced_aborts.get((i, index, -1))
        if forced and ccs in (1, 2):
            self._abort(i, index, sub, forced)
            return
        mux = bytes([index & 0xFF, index >> 8, sub])
        try:
            if ccs == 2:  # initiate upload
                value = od.read(index, sub)
                sess.clear()
                if len(value) <= 4:
                    self._send(
                        reply,
                        bytes([0x43 | ((4 - len(value)) << 2)]) + mux + value.ljust(4, b"\x00"),
                    )
                else:
                    sess.update(up=value, pos=0, toggle=0, index=index, sub=sub)
                    self._send(reply, bytes([0x41]) + mux + len(value).to_bytes(4, "little"))
            elif ccs == 3:  # upload segment
                if "up" not in sess:
                    raise SdoAbort(ABORT_COMMAND, index, sub)
                toggle = (cmd >> 4) & 1
                if toggle != sess["toggle"]:
                    raise SdoAbort(ABORT_TOGGLE, index, sub)
                chunk = sess["up"][sess["pos"] : sess["pos"] + 7]
                sess["pos"] += 7
                last = sess["pos"] >= len(sess["up"])
                head = (toggle << 4) | ((7 - len(chunk)) << 1) | int(last)
                self._send(reply, bytes([head]) + chunk.ljust(7, b"\x00"))
                sess["toggle"] ^= 1
                if last:
                    sess.clear()
            elif ccs == 1:  # initiate download
                sess.clear()
                if cmd & 0x02:  # expedited
                    if cmd & 0x01:
                        payload = data[4 : 8 - ((cmd >> 2) & 3)]
                    else:  # size not indicated: the object's size
                        e = od.entry(index, sub)
                        payload = data[4 : 4 + (e.size if e.kind != "str" else 4)]
                    od.write(index, sub, bytes(payload))
                else:
                    sess.update(down=bytearray(), toggle=0, index=index, sub=sub)
                self._send(reply, bytes([0x60]) + mux + b"\x00" * 4)
            elif ccs == 0:  # download segment
                if "down" not in sess:
                    raise SdoAbort(ABORT_COMMAND, index, sub)
                toggle = (cmd >> 4) & 1
                if toggle != sess["toggle"]:
                    raise SdoAbort(ABORT_TOGGLE, index, sub)
                sess["down"] += data[1 : 8 - ((cmd >> 1) & 7)]
                sess["toggle"] ^= 1
                if cmd & 0x01:
                    buf = bytes(sess["down"])
                    sess.clear()
                    od.write(index, sub, buf)
                self._send(reply, bytes([0x20 | (toggle << 4)]) + b"\x00" * 7)
            else:  # block transfer and unknown specifiers
                raise SdoAbort(ABORT_COMMAND, index, sub)
        except SdoAbort as a:
            self._abort(i, index, sub, a.code)

    # --------------------------------------------------------------- dispatching

    def handle(self, msg: Any) -> None:
        """React to one received frame (with :attr:`lock` held)."""
        self.frames += 1
        if msg.is_error_frame or msg.is_remote_frame or msg.is_extended_id:
            return
        cob, data = msg.arbitration_id, bytes(msg.data)
        if cob == layout.NMT_COB_ID:
            self._nmt(data)
        elif cob == layout.SYNC_COB_ID and len(data) <= 1:
            self._sync()
        elif cob in self._rpdo:
            i, idx, size = self._rpdo[cob]
            if self.bus_off[i]:
                return
            if len(data) != size:
                self._emcy(i, CODE_PDO_LENGTH, 0x11)
                return
            self._rx_flat[idx[1]] = np.frombuffer(data, dtype=np.uint8)[idx[0]]
            self._got_rpdo = True
        elif cob in self._by_sdo:
            i = self._by_sdo[cob]
            if self._talks(i):
                self._sdo_request(i, data)

    def _timers(self, now: float) -> float:
        """Heartbeats and delayed TPDOs that are due; returns seconds to the next one."""
        nxt = 0.05
        for i in range(self.n):
            period = self._od0[i].get(0x1017, 0) / 1000.0
            if period <= 0 or not self._talks(i) or self.no_heartbeat[i]:
                continue
            if now >= self._hb_next[i]:
                self._send(layout.HEARTBEAT_BASE + self.node_ids[i], bytes([int(self.nmt[i])]))
                self._hb_next[i] = max(self._hb_next[i] + period, now)
            nxt = min(nxt, self._hb_next[i] - now)
        return max(0.0, min(nxt, self._send_due(now)))

    def _send_due(self, now: float) -> float:
        """Send the delayed TPDOs that are due (in order); seconds to the next one."""
        nxt = 0.05
        if self._delayed:
            keep = []
            for due, msg in self._delayed:
                if now >= due:
                    try:
                        self.bus.send(msg)
                    except self._can.CanError:
                        pass
                else:
                    keep.append((due, msg))
                    nxt = min(nxt, due - now)
            self._delayed = keep
        return nxt

    def poll(self, timeout: float = 0.01) -> None:
        """Receive and handle one frame (waiting up to ``timeout`` s), then due timers."""
        with self.lock:
            wait = min(timeout, self._timers(time.monotonic()))
        msg = self.bus.recv(wait)
        with self.lock:
            if msg is not None:
                self.handle(msg)
                # Drain what is queued before timers: frames first, as a CAN controller.
                while True:
                    more = self.bus.recv(0.0)
                    if more is None:
                        break
                    self.handle(more)
            self._timers(time.monotonic())

    def run(self, duration: float | None = None) -> None:
        """Poll until :attr:`stopping` or ``duration`` seconds."""
        end = None if duration is None else time.monotonic() + duration
        while not self.stopping and (end is None or time.monotonic() < end):
            self.poll(0.01)

    def start(self) -> CanopenDrives:
        """Run :meth:`run` in a daemon thread (tests, one-process benchmarks)."""
        self._thread = threading.Thread(target=self.run, name="canopen-drives", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop the thread started by :meth:`start`."""
        self.stopping = True
        if self._thread is not None:
            self._thread.join(2.0)
            self._thread = None

    # ----------------------------------------------------------- fault injection

    def _node(self, request: dict[str, Any]) -> int:
        i = int(request["node"])
        if not 0 <= i < self.n:
            raise ValueError(f"node {i} does not exist (0..{self.n - 1}, bus order)")
        return i

    def _drive(self, request: dict[str, Any]) -> int:
        """The drive of ``node`` (position) and ``axis`` (its CiA-402 axis, default 0)."""
        row = self.records[self._node(request)]
        k = int(request.get("axis", 0))
        j = row[k] if 0 <= k < len(row) else None
        if j is None:
            raise ValueError(f"node {request['node']} has no axis {k}")
        return j

    def control(self, request: dict[str, Any]) -> dict[str, Any]:
        """Apply one control request; ``{"ok": True, ...}`` or ``{"ok": False, "error": ...}``.

        ``node`` is the 0-based node position (the drive position with one axis per node);
        requests on a drive (``emcy`` with a fault code, ``clear_drive_fault`` and the
        commissioning ones) take ``axis``, its CiA-402 axis on the node (default 0).
        Requests (``op``): ``status``; ``silence``
        (node, on: no frame sent, heartbeat stops); ``heartbeat`` (node, on: false stops
        only the heartbeat producer, PDOs go on); ``emcy`` (node, code: a 0x603F code of
        drivers.sim.drive.FAULTS faults the drive, which then sends the EMCY; any other code
        is sent as a bare EMCY; persistent); ``clear_drive_fault`` (node); ``sdo_abort``
        (node, index, sub (-1 = all), code; 0 removes); ``tpdo`` (node, mode "drop" or
        "late", count of SYNCs, delay [s] for late); ``identity`` (node, vendor_id,
        product_code: 0x1018 reports these; ``restore``: true puts the configured ones
        back); ``bus_off`` (node, on: the node's controller leaves the bus, on recovery it
        sends EMCY 0x8140); ``push`` (force [N] (3,) world frame at the tool, duration [s],
        ramp [s]: a hand on the true arm from now; answers its start ``t`` [s] of plant time;
        with ``trace`` [s] also a trace from then); ``trace`` (seconds: the true arm's t, q,
        qd at every plant step for that long); ``trace_read`` (the trace so far, ``done``
        once over); ``sto``, ``brake``, ``home_switch``, ``index_phase`` (node and the
        fields of :meth:`drivers.sim.drive.EmulatedDrives.commissioning`); ``stop``.
        """
        op = request.get("op")
        try:
            with self.lock:
                if op == "status":
                    return {"ok": True, **self.status()}
                if op == "silence":
                    self.silent[self._node(request)] = bool(request.get("on", True))
                elif op == "heartbeat":
                    self.no_heartbeat[self._node(request)] = not bool(request.get("on", True))
                elif op == "emcy":
                    j, code = self._drive(request), int(request["code"])
                    kind = _FAULT_KINDS.get(code)
                    if kind is not None:
                        self.drives.inject_fault(j, kind, bool(request.get("persistent", False)))
                    else:
                        i = self.node_of[j]
                        self._emcy(i, code, int(request.get("register", 0x01)), self.axis_of[j])
                elif op == "clear_drive_fault":
                    self.drives.clear_fault(self._drive(request))
                elif op == "sdo_abort":
                    key = (self._node(request), int(request["index"]), int(request.get("sub", -1)))
                    code = int(request["code"])
                    if code:
                        self.forced_aborts[key] = code
                    else:
                        self.forced_aborts.pop(key, None)
                elif op == "tpdo":
                    i, count = self._node(request), int(request.get("count", 1))
                    if request.get("mode", "drop") == "late":
                        self.tpdo_late[i] = count
                        self.tpdo_delay[i] = float(request.get("delay", 0.05))
                    else:
                        self.tpdo_drop[i] = count
                elif op == "identity":
                    self._identity(self._node(request), request)
                elif op == "bus_off":
                    i, on = self._node(request), bool(request.get("on", True))
                    was = bool(self.bus_off[i])
                    self.bus_off[i] = on
                    if was and not on:
                        self._emcy(i, CODE_BUS_OFF_RECOVERED, 0x11)
                elif op == "push":
                    self.drives.push_tool(
                        request["force"],
                        float(request["duration"]),
                        float(request.get("ramp", 0.02)),
                    )
                    if "trace" in request:
                        self.trace.start(float(request["trace"]))
                    return {"ok": True, "t": float(self.drives.plant.t)}  # the push's start
                elif op == "trace":
                    self.trace.start(float(request["seconds"]))
                    return {"ok": True, "t": float(self.drives.plant.t)}
                elif op == "trace_read":
                    return {"ok": True, **self.trace.read()}
                elif op == "stop":
                    self.stopping = True
                elif op in self.drives.COMMISSIONING_OPS:
                    return {"ok": True, **self.drives.commissioning(self._drive(request), request)}
                else:
                    raise ValueError(f"unknown op {op!r}")
        except (KeyError, TypeError, ValueError, IndexError) as exc:
            return {"ok": False, "error": f"{op}: {exc}"}
        return {"ok": True}

    def _identity(self, i: int, request: dict[str, Any]) -> None:
        for sub, key in ((1, "vendor_id"), (2, "product_code"), (3, "revision")):
            saved = self._identity_saved.get((i, sub))
            if request.get("restore"):
                if saved is not None:
                    self._od0[i].set(0x1018, sub, saved)
                    del self._identity_saved[(i, sub)]
            elif key in request:
                if saved is None:
                    self._identity_saved[(i, sub)] = self._od0[i].get(0x1018, sub)
                self._od0[i].set(0x1018, sub, int(request[key]))

    def status(self) -> dict[str, Any]:
        """Counters, NMT state per node and the true arm state (SI)."""
        plant = self.drives.plant
        return {
            "syncs": self.syncs,
            "frames": self.frames,
            "nmt": [int(s) for s in self.nmt],
            "silent": [bool(s) for s in self.silent],
            "bus_off": [bool(s) for s in self.bus_off],
            "t": plant.t,
            "q": plant.q.tolist(),
            "qd": plant.qd.tolist(),
            "tau_applied": plant.tau_applied.tolist(),
            "drive_state": [int(x) for x in self.drives.state],
            "error_code": [int(x) for x in self.drives.tx["error_code"]],
            **self.drives.commissioning_status(),
        }


# ---------------------------------------------------------------------------- EDS


def node_dictionary(drive: Any, node_id: int, name: str = "drive") -> ObjectDictionary:
    """A stand-alone dictionary of one emulated CANopen drive (for the EDS and tests):
    :func:`~drivers.sim.object_dictionary.cia402_dictionary` plus the CANopen objects."""
    from drivers.cia402.pdo import new_rx, new_tx
    from drivers.sim.drive import _gear_fraction
    from drivers.sim.object_dictionary import DriveObjects, cia402_dictionary

    z = np.zeros
    objs = DriveObjects(
        new_rx(1),
        new_tx(1),
        z(1, np.uint16),
        z(1, np.uint32),
        z(1, np.uint32),
        z(1, np.uint16),
        z(1, np.int16),
        z(1, np.uint8),
    )
    motor, shaft = _gear_fraction(drive.gear_ratio)
    od = cia402_dictionary(
        0,
        objs,
        vendor_id=drive.identity.vendor_id,
        product_code=drive.identity.product_code,
        revision=drive.identity.revision or 0,
        serial=0x5100,
        device_name=f"hofto-sim servo {name}",
        counts_per_rev=drive.counts_per_rev,
        gear_motor_revs=motor,
        gear_shaft_revs=shaft,
        rated_torque_mnm=round(drive.rated_torque),
        rated_current_ma=round(drive.rated_current),
    )
    add_canopen_objects(od, node_id)
    return od


_SUBST = {0x1014: 1, 0x1400: 1, 0x1401: 1, 0x1800: 1, 0x1801: 1}  # COB-IDs with $NODEID


def eds_text(od: ObjectDictionary, node_id: int, product: str = "hofto-sim CiA-402 servo") -> str:
    """The dictionary of node ``node_id`` as an EDS (CiA 306) text; node-specific COB-IDs
    are written as ``$NODEID+base``."""
    lines = [
        "; Generated from drivers/sim/object_dictionary.py + drivers/sim/canopen_node.py",
        "; by tools/make_canopen_eds.py. Do not edit: regenerate.",
        "[FileInfo]",
        "FileName=emulated_drive.eds",
        "FileVersion=1",
        "FileRevision=0",
        "EDSVersion=4.0",
        f"Description={product}",
        "CreatedBy=hofto-hw",
        "",
        "[DeviceInfo]",
        "VendorName=hofto-hw",
        f"VendorNumber=0x{od.get(0x1018, 1):08X}",
        f"ProductName={product}",
        f"ProductNumber=0x{od.get(0x1018, 2):08X}",
        f"RevisionNumber=0x{od.get(0x1018, 3):08X}",
        "BaudRate_125=1",
        "BaudRate_250=1",
        "BaudRate_500=1",
        "BaudRate_1000=1",
        "SimpleBootUpMaster=0",
        "SimpleBootUpSlave=1",
        "Granularity=8",
        "DynamicChannelsSupported=0",
        "GroupMessaging=0",
        f"NrOfRXPDO={len(layout.RPDOS)}",
        f"NrOfTXPDO={len(layout.TPDOS)}",
        "LSS_Supported=0",
        "",
        "[DummyUsage]",
        *[f"Dummy000{k}=0" for k in range(1, 8)],
        "",
    ]
    mandatory = [i for i in od.indices() if i in (0x1000, 0x1001, 0x1018)]
    optional = [i for i in od.indices() if i not in mandatory]
    for title, group in (("MandatoryObjects", mandatory), ("OptionalObjects", optional)):
        lines += [f"[{title}]", f"SupportedObjects={len(group)}"]
        lines += [f"{k + 1}=0x{i:04X}" for k, i in enumerate(group)]
        lines.append("")
    lines += ["[ManufacturerObjects]", "SupportedObjects=0", ""]
    for index in mandatory + optional:
        subs = od.subentries(index)
        name = od.object_name(index)
        if len(subs) == 1 and subs[0].subindex == 0:
            lines += [f"[{index:04X}]", *_var_lines(subs[0], name, node_id), ""]
            continue
        lines += [
            f"[{index:04X}]",
            f"ParameterName={name}",
            "ObjectType=0x9",
            f"SubNumber={len(subs)}",
            "",
        ]
        for e in subs:
            lines += [f"[{index:04X}sub{e.subindex:X}]", *_var_lines(e, e.name, node_id), ""]
    return "\n".join(lines)


def _var_lines(e: OdEntry, name: str, node_id: int) -> list[str]:
    access = {"ro": "ro", "rw": "rw", "wo": "wo", "const": "const"}[e.access]
    if e.kind == "str":
        default = e.get_bytes().decode()
    else:
        value = e.get()
        if _SUBST.get(e.index) == e.subindex:
            default = f"$NODEID+0x{value - node_id:X}"
        else:
            default = f"0x{value & 0xFFFFFFFF:X}" if value >= 0 else str(value)
    return [
        f"ParameterName={name}",
        "ObjectType=0x7",
        f"DataType=0x{KINDS[e.kind][1]:04X}",
        f"AccessType={access}",
        f"DefaultValue={default}",
        f"PDOMapping={int(e.pdo_mappable)}",
    ]
