"""CANopen master implementing :class:`drivers.transport.Transport` for CiA-402 drives.

Library split (measured figures in docs/canopen.md):

- **Setup through the ``canopen`` library**: a ``canopen.Network`` on its own python-can bus
  object carries NMT, the SDO client (expedited and segmented, abort codes) and the
  heartbeat/EMCY subscriptions, dispatched by its notifier thread. That bus is filtered to
  EMCY, SDO answers and heartbeats, so the notifier thread does not wake for PDOs.
- **Cyclic path on python-can directly**: a second bus object on the same channel, filtered
  to the TPDO COB-IDs. :meth:`CANopenTransport.exchange` runs in the caller's thread: it
  fills preallocated RPDO messages from ``rx`` (one ``np.take`` per frame), sends them, sends
  the SYNC (the loop is the SYNC producer: canopen's SYNC thread jitters by milliseconds),
  then receives TPDOs until all arrived or the per-cycle deadline passed. canopen's own PDO
  objects decode through per-variable callbacks in its notifier thread, a thread hop and
  Python objects per value; the direct path is one scatter per frame in the caller's thread.

Start-up (:meth:`CANopenTransport.open`, blocking; errors name the node and the values):
bus-load check, NMT reset communication and boot-up of every node, identity 0x1018 check,
PDO communication and mapping parameters by SDO (CiA 301 order: PDO invalid, mapping count
0, entries, count, valid) read back and compared, heartbeat producer 0x1017, NMT start and
wait for every node's operational heartbeat.

Every cycle (:meth:`exchange`, never raises): TPDOs that arrived after the last deadline
are drained first (counted late, not used), RPDOs then SYNC are sent, TPDOs collected until
``tpdo_deadline``. Which SYNC a TPDO answers: CAN frames carry no sequence number, but a
synchronous TPDO answers every SYNC once, one node sends each COB-ID and CAN delivers in
order; so the master counts, per node and TPDO, the SYNCs not answered yet. A frame that
arrives while an older SYNC is still unanswered is that older SYNC's answer: counted late,
not used, and this cycle's is still missing (a stream late by whole cycles, which lands in
a later cycle's window, reads as late every cycle, never fresh). A frame lost on the way
reads the same as such a lag (nothing tells the two apart): after ``tpdo_resync`` of an
unbroken backlog the backlog is written off (:attr:`resyncs` counts it), so a lost frame
costs ``tpdo_resync`` of stale cycles, not the session. Missing TPDOs give
:data:`~drivers.transport.STATUS_PARTIAL`, TPDOs of an older SYNC only
:data:`STATUS_TPDO_LATE` (:meth:`missing_nodes` names the nodes; both are not ok, so a
streak of them is a bus loss in safety.bus_health), a heartbeat older than
``heartbeat_timeout`` gives :data:`STATUS_HEARTBEAT_LOST`, a node that left operational
:data:`STATUS_NOT_OPERATIONAL`, a send failure (bus-off, buffer full)
:data:`~drivers.transport.STATUS_BUS_ERROR`. The error code of each node's last EMCY is
written to ``tx["error_code"]``; :meth:`problems` says in words what is wrong, per node.

Multi-axis nodes (``bus.drives[i].device`` / ``device_axis``, CiA 402-1: axis k's objects at
0x6000 + 0x800·k): NMT, heartbeat, SDO, EMCY and the TPDO bookkeeping are per node (device),
the CiA-402 state and the process image per axis (:class:`~drivers.cia402.wire.WireImage`
with ``serve``). A node fault (heartbeat lost, left operational, TPDOs missing) names the
node and every joint on it. SDOs of a joint reach its axis's objects (0x6000..0x67FF shifted
by 0x800·k); start-up SDOs and PDO configuration address the node as the profile names its
objects. An EMCY carries its axis when the profile says in which byte
(``canopen.emcy_axis_byte``); otherwise its code goes to every axis of the node and
:meth:`problems` reads 0x603F of each axis by SDO. PDO COB-IDs: the profile's, checked for
clashes across the bus at construction (:func:`drivers.canopen.layout.cob_id_clashes`).
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Sequence
from typing import Any

import numpy as np

from drivers.canopen import layout
from drivers.canopen.busload import bus_load, check_bus_load
from drivers.canopen.errors import CANopenError, IdentityMismatchError, NodeMissingError
from drivers.canopen.socket_buffer import widen_receive_buffer
from drivers.cia402.codes import describe_error_code
from drivers.cia402.pdo import parse_mapping_value
from drivers.transport import (
    STATUS_BUS_ERROR,
    STATUS_NOT_OPEN,
    STATUS_OK,
    STATUS_PARTIAL,
    STATUS_TEXT,
    SdoAbortError,
    Transport,
)

STATUS_HEARTBEAT_LOST = 100
STATUS_NOT_OPERATIONAL = 101
STATUS_TPDO_LATE = 102
STATUS_TEXT.setdefault(STATUS_HEARTBEAT_LOST, "CANopen heartbeat lost (a node went silent)")
STATUS_TEXT.setdefault(STATUS_NOT_OPERATIONAL, "a CANopen node left the operational state")
STATUS_TEXT.setdefault(
    STATUS_TPDO_LATE, "a CANopen node's TPDOs answer an older SYNC (late by whole cycles)"
)
_ABORT_TIMEOUT = 0x05040000


class _Pdo:
    """One PDO of one node as its profile runs it: communication and mapping objects,
    COB-ID, transmission type, where its payload sits in the axis's wire bytes."""

    def __init__(self, name: str, comm: int, spec: Any, cob: int, ttype: int, offset: int):
        self.name = name
        self.comm_index = comm
        self.map_index = spec.index
        self.fixed = spec.fixed
        self.entries = [(e.index, e.subindex, e.bits) for e in spec.entries]
        self.cob = cob
        self.transmission = ttype
        self.offset = offset
        self.size = spec.bits // 8


class CANopenTransport(Transport):
    """CiA-402 drives on CANopen (see the module docstring).

    ``channel``: python-can channel; ``drives``: one DriveConfig per node (identity
    checked); ``cycle_time`` [s]: 1 / loop rate; ``node_ids``: CANopen node ids (default
    1..n). ``heartbeat_time`` [s]: producer time written to 0x1017; ``heartbeat_timeout``
    [s]: consumer limit (default 3 x producer); ``tpdo_deadline`` [s]: how long a cycle waits
    for TPDOs after its SYNC (default 0.8 cycle); ``tpdo_resync`` [s]: how long a node's TPDOs
    may lag before the backlog is written off (default ``heartbeat_timeout``; see the module
    docstring: it must be longer than the bus-loss streak, or a lag would end unreported).
    ``bus_kwargs``: extra python-can options. ``node_ids`` has one id per node (device):
    with multi-axis drives fewer than ``drives``.
    """

    def __init__(
        self,
        channel: str,
        drives: Sequence[Any],
        cycle_time: float,
        axis_names: list[str] | None = None,
        *,
        can_interface: str = "socketcan",
        node_ids: Sequence[int] | None = None,
        bitrate: int = 1_000_000,
        data_bitrate: int | None = None,
        load_limit: float = 0.7,
        heartbeat_time: float = 0.05,
        heartbeat_timeout: float | None = None,
        tpdo_deadline: float | None = None,
        tpdo_resync: float | None = None,
        sdo_timeout: float = 0.5,
        boot_timeout: float = 3.0,
        bus_kwargs: dict[str, Any] | None = None,
        profiles: Sequence[Any] | None = None,
    ) -> None:
        super().__init__(len(drives), cycle_time, axis_names)
        from hofto_hw.config.drives import device_map

        self.channel = channel
        self.can_interface = can_interface
        self.drives = list(drives)
        #: (node position, CiA-402 axis of that node) per axis
        self.serve = device_map(self.drives)
        #: number of nodes (devices); one NMT state, heartbeat and SDO server each
        self.n_devices = n = max(d for d, _k in self.serve) + 1
        #: the node position of each axis, (n_axes,)
        self._node_of = np.array([d for d, _k in self.serve], dtype=np.intp)
        #: the first axis of each node (its profile, identity and who-string)
        self._first = [[d for d, _k in self.serve].index(j) for j in range(n)]
        #: the axes of each node, in device-axis order
        self._axes_of = [
            sorted(
                (i for i, (d, _k) in enumerate(self.serve) if d == j),
                key=lambda i: self.serve[i][1],
            )
            for j in range(n)
        ]
        self.node_ids = list(node_ids) if node_ids is not None else list(range(1, n + 1))
        if len(self.node_ids) != n:
            raise ValueError(f"{len(self.node_ids)} node ids for {n} nodes ({self.n_axes} drives)")
        self.bitrate = bitrate
        self.data_bitrate = data_bitrate
        self.load_limit = load_limit
        self.heartbeat_time = heartbeat_time
        self.heartbeat_timeout = heartbeat_timeout or 3.0 * heartbeat_time
        self.tpdo_deadline = tpdo_deadline or 0.8 * cycle_time
        self.tpdo_resync = tpdo_resync or self.heartbeat_timeout
        self._resync_cycles = max(1, round(self.tpdo_resync / cycle_time))
        self.sdo_timeout = sdo_timeout
        self.boot_timeout = boot_timeout
        self.bus_kwargs = dict(bus_kwargs or {})
        self.network: Any = None
        #: canopen RemoteNode per node (device)
        self.nodes: list[Any] = []
        #: SDOs address the node as named (start-up, PDO configuration), not an axis's objects
        self._raw_sdo = False
        self._cyc: Any = None
        self.is_open = False
        # Counters (read outside the tick).
        self.cycles = 0
        self.partial_cycles = 0
        self.late_frames = 0
        self.bad_frames = 0
        self.send_errors = 0
        #: backlogs written off after ``tpdo_resync`` (a lost frame or a lasting lag)
        self.resyncs = 0
        #: emergencies received, newest last: (axis, error code, error register, time); the
        #: axis is -1 - node position when the EMCY of a multi-axis node names no axis
        self.emergencies: deque[tuple[int, int, int, float]] = deque(maxlen=64)
        # Per-node state written by the notifier thread (plain numpy stores).
        self._hb_time = np.zeros(n)
        self._hb_state = np.full(n, -1, dtype=np.int16)
        self._booted = np.zeros(n, dtype=bool)
        #: per axis: the error code of its node's last EMCY (for that axis, or naming none)
        self._emcy_code = np.zeros(self.n_axes, dtype=np.uint16)
        #: per node: its last EMCY named no axis (multi-axis node, profile without the byte)
        self._emcy_unplaced = np.zeros(n, dtype=bool)
        from drivers.cia402.profiles import builtin_profile, layout_of
        from drivers.cia402.wire import WireImage

        #: one DriveProfile per node (None in the list: the built-in two RPDOs / TPDOs)
        self.profiles = [
            p if p is not None else builtin_profile("canopen")
            for p in (profiles if profiles is not None else [None] * self.n_axes)
        ]
        self.startup_written = 0
        from drivers.cia402.profiles import refuse_unknown_units

        refuse_unknown_units(self.axis_names, self.profiles)
        self.use_fallbacks(self.profiles)
        # the wire image of every node: its PDO payloads end to end (RPDOs / TPDOs), one
        # encode and one decode per cycle; the frames are slices of it
        self.wire = WireImage(
            [layout_of(self.profiles[i]) for i in self._first], self.axis_names, self.serve
        )
        self.wire.bind_master(self.rx, self.tx)
        from drivers.cia402.profiles import csp_adapter

        self.wire.set_adapter(
            csp_adapter(self.profiles, cycle_time, [d.counts_per_rev for d in drives])
        )  # ip / pv drives
        self._rpdos: list[list[_Pdo]] = []
        self._tpdos: list[list[_Pdo]] = []
        for prof, nid in zip([self.profiles[i] for i in self._first], self.node_ids, strict=True):
            comm = prof.canopen
            for out, pdos, comms, base, kind in (
                (self._rpdos, prof.rx_pdos, comm.rpdo, 0x1400, "RPDO"),
                (self._tpdos, prof.tx_pdos, comm.tpdo, 0x1800, "TPDO"),
            ):
                off, row = 0, []
                for spec, c in zip(pdos, comms, strict=True):
                    number = (spec.index & 0x1FF) + 1
                    row.append(
                        _Pdo(
                            f"{kind}{number}",
                            base + (spec.index & 0x1FF),
                            spec,
                            c.cob_id_base + nid,
                            c.transmission_type,
                            off,
                        )
                    )
                    off += row[-1].size
                out.append(row)
        clashes = layout.cob_id_clashes(
            [
                (nid, self._who_node(d), [(p.name, p.cob) for p in self._rpdos[d] + self._tpdos[d]])
                for d, nid in enumerate(self.node_ids)
            ]
        )
        if clashes:
            raise CANopenError(f"CAN channel {channel}: {clashes[0]}")
        # Cyclic-path buffers.
        n_t = max(len(row) for row in self._tpdos)
        #: TPDO slots a node does not have: always "got", never owed
        self._unused = np.array(
            [[k >= len(row) for k in range(n_t)] for row in self._tpdos], dtype=bool
        )
        self._used = (~self._unused).astype(np.int64)
        self._n_used = int(self._used.sum())
        self._got = np.zeros((n, n_t), dtype=bool)
        self._got_any = np.zeros(n, dtype=bool)
        #: SYNCs each node's TPDO has not answered yet (1 while the cycle's answer is due)
        self._owed = np.zeros((n, n_t), dtype=np.int64)
        #: consecutive cycles that ended with an unanswered SYNC, per node and TPDO
        self._behind = np.zeros((n, n_t), dtype=np.int64)
        self._owing = np.zeros((n, n_t), dtype=bool)
        self._old = np.zeros(n, dtype=bool)  # a frame of an older SYNC came this cycle
        self._late_nodes = np.zeros(n, dtype=bool)
        self._age = np.zeros(n)
        self._lost = np.zeros(n, dtype=bool)
        self._not_op = np.zeros(n, dtype=bool)
        #: per node, latched since open: its heartbeat was lost / it left operational
        self._lost_seen = np.zeros(n, dtype=bool)
        self._left_seen = np.zeros(n, dtype=bool)
        self._missing = np.zeros(n, dtype=bool)
        self._tx_err = self.tx["error_code"]
        #: axes whose drive does not map 0x603F: the error code of their node's last EMCY
        self._err_by_emcy = ~self.wire.present["error_code"]
        self._rpdo_msgs: list[Any] = []
        self._rpdo_views: list[np.ndarray] = []
        self._rpdo_src: list[np.ndarray] = []
        #: TPDO COB-ID -> (slot, node, the payload's bytes in the wire image, payload size)
        self._tpdo_slots: dict[int, tuple[int, int, np.ndarray, int]] = {}
        for i in range(n):
            base = self.wire.tx_offsets[i]
            for k, p in enumerate(self._tpdos[i]):
                view = self.wire.tx_in[base + p.offset : base + p.offset + p.size]
                self._tpdo_slots[p.cob] = (k, i, view, p.size)
        self._sync_msg: Any = None

    @classmethod
    def from_config(
        cls, bus: Any, axis_names: list[str] | None = None, *, cycle_time: float
    ) -> CANopenTransport:
        """From a :class:`hofto_hw.config.drives.BusConfig` with ``transport: canopen``;
        ``cycle_time`` [s] is the system config's 1 / loop.rate_hz (as EtherCAT's)."""
        from drivers.cia402.profiles import profiles_for
        from hofto_hw.config.drives import CANopenOptions

        o = bus.canopen or CANopenOptions()
        return cls(
            bus.interface,
            bus.drives,
            cycle_time,
            axis_names,
            can_interface=o.can_interface,
            node_ids=o.node_ids,
            bitrate=o.bitrate,
            data_bitrate=o.data_bitrate,
            load_limit=o.load_limit,
            heartbeat_time=o.heartbeat_time,
            heartbeat_timeout=o.heartbeat_timeout,
            tpdo_deadline=o.tpdo_deadline,
            tpdo_resync=o.tpdo_resync,
            sdo_timeout=o.sdo_timeout,
            boot_timeout=o.boot_timeout,
            profiles=profiles_for(bus.drives, "canopen"),
        )

    # ------------------------------------------------------------------ naming

    def _who(self, axis: int) -> str:
        d, k = self.serve[axis]
        on = f" axis {k}" if len(self._axes_of[d]) > 1 or self.profiles[axis].axes > 1 else ""
        return f"node {self.node_ids[d]}{on} ({self.axis_names[axis]})"

    def _who_node(self, d: int) -> str:
        """Node ``d`` (position) with every joint it drives, e.g. 'node 2 (joint_3, joint_4)'."""
        names = ", ".join(self.axis_names[i] for i in self._axes_of[d])
        return f"node {self.node_ids[d]} ({names})"

    def load(self) -> Any:
        """Worst-case bus load of this configuration (:class:`BusLoad`)."""
        sizes = [p.size for row in self._rpdos + self._tpdos for p in row]
        return bus_load(
            [0] + sizes,
            1.0 / self.cycle_time,
            self.bitrate,
            self.data_bitrate,
            self.load_limit,
        )

    # ---------------------------------------------------------------- start-up

    def _bus(self, filters: list[dict[str, int]] | None) -> Any:
        import can

        kw = dict(self.bus_kwargs)
        if self.data_bitrate is not None:
            kw.setdefault("fd", True)
            if self.can_interface not in ("virtual", "udp_multicast"):
                kw.setdefault("data_bitrate", self.data_bitrate)
        if self.can_interface not in ("virtual", "udp_multicast"):
            kw.setdefault("bitrate", self.bitrate)
        try:
            bus = can.Bus(
                interface=self.can_interface, channel=self.channel, can_filters=filters, **kw
            )
        except (can.CanError, OSError, ValueError, ImportError) as exc:
            raise CANopenError(
                f"bus.interface: cannot open CAN channel {self.channel!r} with python-can "
                f"interface {self.can_interface!r}: {exc}"
            ) from None
        widen_receive_buffer(bus)  # a UDP socket drops what a CAN controller would keep
        return bus

    def open(self) -> None:
        """Bring every node to operational (see the module docstring); raises CANopenError."""
        if self.is_open:
            return
        check_bus_load(self.load(), "bus.canopen")
        import can
        import canopen

        exact = 0x7FF
        setup_filters = [
            {"can_id": base + nid, "can_mask": exact, "extended": False}
            for nid in self.node_ids
            for base in (layout.EMCY_BASE, layout.SDO_TX_BASE, layout.HEARTBEAT_BASE)
        ]
        cyc_filters = [
            {"can_id": cob, "can_mask": exact, "extended": False} for cob in self._tpdo_slots
        ]
        setup_bus = self._bus(setup_filters)
        try:
            # Kernel filters on socketcan. Elsewhere python-can filters in Python, and its
            # recv(0.0) then returns None at the first foreign frame queued (an SDO answer,
            # a heartbeat, on udp_multicast our own frames): the drain would stop short and
            # this bus fall behind by what the setup queued (measured: udp_multicast's socket
            # full of the SDO exchange dropped the first SYNC's answers). _slot filters.
            self._cyc = self._bus(cyc_filters if self.can_interface == "socketcan" else None)
            net = canopen.Network(setup_bus)
            net.NOTIFIER_CYCLE = 0.1
            net.connect()
            self.network = net
            self.nodes = []
            for d, nid in enumerate(self.node_ids):
                node = canopen.RemoteNode(nid, canopen.ObjectDictionary())
                node.sdo.RESPONSE_TIMEOUT = self.sdo_timeout
                node.sdo.MAX_RETRIES = 2  # udp_multicast drops frames in bursts
                net.add_node(node)
                self.nodes.append(node)
                net.subscribe(layout.HEARTBEAT_BASE + nid, self._heartbeat_cb(d))
                net.subscribe(layout.EMCY_BASE + nid, self._emcy_cb(d))
            self._prepare_messages(can)
            self._start(net)
            while self._cyc.recv(0.0) is not None:  # what the setup queued: not a TPDO
                pass
        except BaseException:
            self._shutdown()
            raise
        if self.derived is not None:
            self.derived.reset()
        self.is_open = True

    def _heartbeat_cb(self, d: int) -> Any:
        def on_heartbeat(_can_id: int, data: bytes, _timestamp: float) -> None:
            if data:
                state = data[0] & 0x7F
                self._hb_state[d] = state
                self._hb_time[d] = time.monotonic()
                if state == layout.NMT_BOOTUP:
                    self._booted[d] = True

        return on_heartbeat

    def _emcy_cb(self, d: int) -> Any:
        axes = self._axes_of[d]
        by_device_axis = {self.serve[i][1]: i for i in axes}
        where = self.profiles[axes[0]].canopen.emcy_axis_byte
        single = len(axes) == 1 and self.profiles[axes[0]].axes == 1

        def on_emcy(_can_id: int, data: bytes, _timestamp: float) -> None:
            if len(data) < 3:
                return
            code = data[0] | (data[1] << 8)
            axis = axes[0] if single else None
            if axis is None and where is not None and len(data) > where:
                axis = by_device_axis.get(data[where])
            now = time.monotonic()
            if axis is not None:
                self._emcy_code[axis] = code
                self._emcy_unplaced[d] = False
                self.emergencies.append((axis, code, data[2], now))
            else:  # the EMCY names no axis this bus runs: every axis of the node gets it
                for i in axes:
                    self._emcy_code[i] = code
                self._emcy_unplaced[d] = bool(code)
                self.emergencies.append((-1 - d, code, data[2], now))

        return on_emcy

    def _prepare_messages(self, can: Any) -> None:
        fd = self.data_bitrate is not None
        self._rpdo_msgs, self._rpdo_views, self._rpdo_src = [], [], []
        for d in range(self.n_devices):
            base = self.wire.rx_offsets[d]
            for p in self._rpdos[d]:
                data = bytearray(p.size)
                msg = can.Message(arbitration_id=p.cob, data=data, is_extended_id=False, is_fd=fd)
                self._rpdo_msgs.append(msg)
                self._rpdo_views.append(np.frombuffer(msg.data, dtype=np.uint8))
                self._rpdo_src.append(self.wire.rx_out[base + p.offset : base + p.offset + p.size])
        self._sync_msg = can.Message(
            arbitration_id=layout.SYNC_COB_ID, data=b"", is_extended_id=False
        )

    def _wait(self, done: Any, timeout: float) -> bool:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if done():
                return True
            time.sleep(0.002)
        return bool(done())

    def _start(self, net: Any) -> None:
        self._booted.fill(False)
        net.nmt.send_command(layout.NMT_RESET_COMM)
        if not self._wait(lambda: self._booted.all(), self.boot_timeout):
            missing = [self._who_node(d) for d in np.flatnonzero(~self._booted)]
            raise NodeMissingError(
                f"CAN channel {self.channel}: no boot-up message from {', '.join(missing)} "
                f"within {self.boot_timeout:g} s after NMT reset communication"
            )
        from drivers.cia402.profiles import startup_int

        self.startup_written = 0
        self._raw_sdo = True  # the node's objects as the profile names them
        try:
            for d in range(self.n_devices):
                i = self._first[d]
                self._check_identity(i)
                prof = self.profiles[i]
                for w in prof.startup:
                    value = startup_int(prof, w.index, w.subindex, w.value, self.cycle_time)
                    data = (value & ((1 << w.bits) - 1)).to_bytes(w.bits // 8, "little")
                    self.sdo_write(i, w.index, w.subindex, data)
                    self.startup_written += 1
                for p in self._rpdos[d] + self._tpdos[d]:
                    self._map_pdo(i, p)
                ms = prof.canopen.heartbeat_ms
                if ms is None:
                    ms = max(1, round(self.heartbeat_time * 1000))
                self.write_value(i, 0x1017, 0, "u16", ms)
        finally:
            self._raw_sdo = False
        self.rx.fill(0)
        self._hb_state.fill(-1)
        net.nmt.send_command(layout.NMT_START)
        if not self._wait(
            lambda: bool((self._hb_state == layout.NMT_OPERATIONAL).all()), self.boot_timeout
        ):
            bad = [
                f"{self._who_node(d)} reports "
                + layout.NMT_STATE_NAMES.get(int(s), "no heartbeat" if s < 0 else f"state {s}")
                for d, s in enumerate(self._hb_state)
                if s != layout.NMT_OPERATIONAL
            ]
            raise NodeMissingError(
                f"CAN channel {self.channel}: not operational {self.boot_timeout:g} s after "
                f"NMT start: {'; '.join(bad)}"
            )
        self._hb_time.fill(time.monotonic())
        self._lost_seen.fill(False)
        self._left_seen.fill(False)
        self._owed.fill(0)
        self._behind.fill(0)

    def _check_identity(self, i: int) -> None:
        ident = self.drives[i].identity
        if not (ident.vendor_id or ident.product_code):
            return
        checks = [(1, "vendor id", ident.vendor_id), (2, "product code", ident.product_code)]
        if ident.revision is not None:
            checks.append((3, "revision", ident.revision))
        for sub, what, want in checks:
            got = self.read_value(i, 0x1018, sub, "u32")
            if got != want:
                d = self.serve[i][0]
                raise IdentityMismatchError(
                    f"bus.drives[{i}].identity: {self._who_node(d)} reports {what} "
                    f"0x{got:08X} (0x1018:{sub}), expected 0x{want:08X}",
                    self.node_ids[d],
                    what,
                    want,
                    got,
                )

    def _map_pdo(self, i: int, p: _Pdo) -> None:
        """Communication parameters and (when configurable) the mapping of one PDO in the
        CiA 301 order (PDO invalid, transmission type, count 0, entries, count, valid), the
        mapping read back and compared with the profile."""
        self.write_value(i, p.comm_index, 1, "u32", p.cob | layout.COB_ID_INVALID)
        self.write_value(i, p.comm_index, 2, "u8", p.transmission)
        if not p.fixed:
            self.write_value(i, p.map_index, 0, "u8", 0)
            for sub, (index, subindex, bits) in enumerate(p.entries, start=1):
                value = (index << 16) | (subindex << 8) | bits
                self.write_value(i, p.map_index, sub, "u32", value)
            self.write_value(i, p.map_index, 0, "u8", len(p.entries))
        self.write_value(i, p.comm_index, 1, "u32", p.cob)
        count = self.read_value(i, p.map_index, 0, "u8")
        found = [
            parse_mapping_value(self.read_value(i, p.map_index, s, "u32"))[:3]
            for s in range(1, count + 1)
        ]
        if found != p.entries:
            who = self._who_node(self.serve[i][0])
            raise CANopenError(
                f"{who}: {p.name} mapping 0x{p.map_index:04X} reads back as "
                f"{_fmt_map(found)}, profile {self.profiles[i].name} expects "
                f"{_fmt_map(p.entries)}"
            )
        cob = self.read_value(i, p.comm_index, 1, "u32")
        if cob != p.cob:
            who = self._who_node(self.serve[i][0])
            raise CANopenError(
                f"{who}: {p.name} COB-ID 0x{p.comm_index:04X}:01 reads back as "
                f"0x{cob:08X}, expected 0x{p.cob:08X}"
            )

    # ------------------------------------------------------------------- cycle

    def exchange(self) -> int:
        """RPDOs, SYNC, TPDOs until the deadline; returns a status code. Never raises."""
        if not self.is_open:
            return STATUS_NOT_OPEN
        self.cycles += 1
        bus = self._cyc
        owed, got = self._owed, self._got
        try:
            # TPDOs that missed the last deadline answer an older SYNC: counted, not used
            while True:
                m = bus.recv(0.0)
                if m is None:
                    break
                slot = self._slot(m)
                if slot is not None:
                    self.late_frames += 1
                    if owed[slot] > 0:
                        owed[slot] -= 1
            self.wire.encode_rx()
            for msg, view, src in zip(
                self._rpdo_msgs, self._rpdo_views, self._rpdo_src, strict=False
            ):
                np.copyto(view, src)
                bus.send(msg)
            bus.send(self._sync_msg)
            np.add(owed, self._used, out=owed)
            np.copyto(got, self._unused)
            self._old.fill(False)
            pending = self._n_used
            deadline = time.monotonic() + self.tpdo_deadline
            while pending:
                remaining = deadline - time.monotonic()
                if remaining <= 0.0:
                    break
                m = bus.recv(remaining)
                if m is None:
                    break
                slot = self._slot(m)
                if slot is None:
                    continue
                if owed[slot] != 1:
                    # >1: the answer to an older SYNC (the node's frames come in order), its
                    # data one or more cycles old; this SYNC's answer is still to come.
                    # 0: no SYNC left to answer (a duplicate): never data
                    self.late_frames += 1
                    if owed[slot] > 1:
                        owed[slot] -= 1
                        self._old[slot[0]] = True
                    continue
                owed[slot] = 0
                self._store(m)
                got[slot] = True
                pending -= 1
        except Exception:  # python-can raises CanError/OSError on bus-off, buffer full
            self.send_errors += 1
            return STATUS_BUS_ERROR
        self._write_off_backlog()
        self.wire.decode_tx()
        if self.derived is not None:
            self.derived.apply(self.sample_dt)
        np.copyto(self._tx_err, self._emcy_code, where=self._err_by_emcy)
        now = time.monotonic()
        np.subtract(now, self._hb_time, out=self._age)
        np.greater(self._age, self.heartbeat_timeout, out=self._lost)
        if self._lost.any():
            np.logical_or(self._lost_seen, self._lost, out=self._lost_seen)
            return STATUS_HEARTBEAT_LOST
        np.not_equal(self._hb_state, layout.NMT_OPERATIONAL, out=self._not_op)
        if self._not_op.any():
            np.logical_or(self._left_seen, self._not_op, out=self._left_seen)
            return STATUS_NOT_OPERATIONAL
        if pending:
            self.partial_cycles += 1
            np.all(got, axis=1, out=self._got_any)
            np.logical_not(self._got_any, out=self._missing)
            np.logical_and(self._missing, self._old, out=self._late_nodes)
            return STATUS_TPDO_LATE if self._late_nodes.any() else STATUS_PARTIAL
        self._missing.fill(False)
        self._late_nodes.fill(False)
        return STATUS_OK

    def _write_off_backlog(self) -> None:
        """After ``tpdo_resync`` of unanswered SYNCs in a row, forget them (no allocation on
        the usual path): a frame lost on the way would otherwise make every later answer of
        its node read as an older SYNC's for good."""
        np.greater(self._owed, 0, out=self._owing)
        np.add(self._behind, 1, out=self._behind)
        np.multiply(self._behind, self._owing, out=self._behind)
        np.greater_equal(self._behind, self._resync_cycles, out=self._owing)
        if self._owing.any():
            np.copyto(self._owed, 0, where=self._owing)
            np.copyto(self._behind, 0, where=self._owing)
            self.resyncs += 1

    def _slot(self, m: Any) -> tuple[int, int] | None:
        """(node, TPDO number) of a well-formed TPDO frame, else None."""
        hit = self._tpdo_slots.get(m.arbitration_id)
        if hit is None or m.is_error_frame or m.is_remote_frame:
            return None
        k, i, _view, size = hit
        if len(m.data) != size:
            self.bad_frames += 1
            return None
        return i, k

    def _store(self, m: Any) -> None:
        """Copy a TPDO frame's payload into its place in the wire image (decoded into ``tx``
        once per cycle)."""
        view = self._tpdo_slots[m.arbitration_id][2]
        view[:] = np.frombuffer(m.data, dtype=np.uint8)

    # ---------------------------------------------------------------------- NMT

    def nmt(self, command: str, axis: int | None = None) -> None:
        """Send NMT ``command`` (a key of :data:`~drivers.canopen.layout.NMT_COMMANDS`) to
        one node (the node of ``axis``: every axis of a multi-axis node) or to all.

        Outside the tick. A node that leaves operational makes :meth:`exchange` return
        :data:`STATUS_NOT_OPERATIONAL` once its heartbeat says so.
        """
        if command not in layout.NMT_COMMANDS:
            raise CANopenError(
                f"unknown NMT command {command!r} (known: {', '.join(layout.NMT_COMMANDS)})"
            )
        if self.network is None:
            raise CANopenError(f"NMT {command}: the bus is not open")
        code = layout.NMT_COMMANDS[command]
        if axis is None:
            self.network.nmt.send_command(code)
        else:
            self._check_axis(axis)
            self.nodes[self._node_of[axis]].nmt.send_command(code)

    # ----------------------------------------------------------- diagnostics

    def missing_nodes(self) -> list[str]:
        """Nodes (with their joints) whose TPDOs of the last cycle's SYNC did not all arrive
        in time."""
        return [self._who_node(d) for d in np.flatnonzero(self._missing)]

    def node_fault_history(self) -> list[str]:
        """Nodes whose heartbeat was lost or that left operational in a cycle since
        :meth:`open` (latched by :meth:`exchange`), each with every joint it drives; still
        readable after :meth:`close` (a run's summary)."""
        out = []
        for d in range(self.n_devices):
            if self._lost_seen[d]:
                out.append(f"{self._who_node(d)}: heartbeat lost")
            if self._left_seen[d]:
                out.append(f"{self._who_node(d)}: left operational")
        return out

    def node_fault_axes(self) -> np.ndarray:
        """Per axis, bool (n_axes,): its node's heartbeat is lost or it left operational (a
        node fault: every axis of the node). Outside the tick."""
        now = time.monotonic()
        bad = (now - self._hb_time > self.heartbeat_timeout) | (
            self._hb_state != layout.NMT_OPERATIONAL
        )
        return bad[self._node_of]

    def problems(self) -> list[str]:
        """What is wrong on the bus, one line per node and cause, naming every joint of the
        node (outside the tick)."""
        out = []
        now = time.monotonic()
        for i in range(self.n_devices):
            who = self._who_node(i)
            age = now - self._hb_time[i]
            if age > self.heartbeat_timeout:
                out.append(
                    f"{who}: heartbeat lost (none for {age:.2f} s, limit "
                    f"{self.heartbeat_timeout:g} s)"
                )
            elif self._hb_state[i] != layout.NMT_OPERATIONAL:
                state = layout.NMT_STATE_NAMES.get(int(self._hb_state[i]), "unknown state")
                out.append(f"{who}: left operational, heartbeat reports {state}")
            if self._missing[i]:
                behind = int(self._owed[i].max())
                out.append(
                    f"{who}: TPDOs missing or late (not within {self.tpdo_deadline * 1e3:.1f} ms "
                    "of the SYNC"
                    + (
                        f"; the last ones answered a SYNC {behind} cycle(s) older)"
                        if self._late_nodes[i]
                        else ")"
                    )
                )
            out += self._emcy_problems(i)
        return out

    def _emcy_problems(self, d: int) -> list[str]:
        """The node's emergencies in words: per axis when the EMCY named it, else per axis
        from 0x603F read by SDO (the node's code when the read fails)."""
        axes = self._axes_of[d]
        if not self._emcy_unplaced[d]:
            return [
                f"{self._who(i)}: emergency {describe_error_code(int(self._emcy_code[i]))}"
                for i in axes
                if self._emcy_code[i]
            ]
        out = []
        for i in axes:
            try:
                code = self.read_value(i, 0x603F, 0, "u16")
                how = "0x603F"
            except Exception:  # no SDO answer: the node's EMCY code is what is known
                code, how = int(self._emcy_code[i]), "node EMCY, axis unknown"
            if code:
                out.append(f"{self._who(i)}: emergency {describe_error_code(code)} ({how})")
        return out

    def emergency_messages(self) -> list[str]:
        """Every EMCY received (oldest first) in words, e.g. 'node 2 (joint_2): EMCY 0x2310
        continuous over-current, error register 0x03'."""
        out = []
        for i, code, reg, _t in self.emergencies:
            who = self._who(i) if i >= 0 else self._who_node(-1 - i)
            out.append(
                f"{who}: EMCY {describe_error_code(code)}, error register 0x{reg:02X}"
                if code
                else f"{who}: EMCY error reset (no error)"
            )
        return out

    # --------------------------------------------------------------------- SDO

    def _sdo(self, axis: int, index: int, subindex: int, action: str, data: bytes = b"") -> bytes:
        self._check_axis(axis)
        if self.network is None:
            raise CANopenError(f"{self._who(axis)}: SDO {action} before the bus was opened")
        import canopen

        d, k = self.serve[axis]
        if not self._raw_sdo and 0x6000 <= index < 0x6800:
            index += 0x800 * k  # axis k of a multi-axis node (CiA 402-1)
        node = self.nodes[d]
        device = f"{self.axis_names[axis]}, node {self.node_ids[d]}"
        try:
            if action == "read":
                return bytes(node.sdo.upload(index, subindex))
            node.sdo.download(index, subindex, bytes(data))
            return b""
        except canopen.SdoAbortedError as exc:
            raise SdoAbortError(axis, index, subindex, exc.code, action, device) from None
        except canopen.SdoCommunicationError:
            raise SdoAbortError(axis, index, subindex, _ABORT_TIMEOUT, action, device) from None

    def sdo_read(self, axis: int, index: int, subindex: int) -> bytes:
        """SDO upload through canopen's SDO client; raises SdoAbortError naming the node."""
        return self._sdo(axis, index, subindex, "read")

    def sdo_write(self, axis: int, index: int, subindex: int, data: bytes) -> None:
        """SDO download through canopen's SDO client; raises SdoAbortError naming the node."""
        self._sdo(axis, index, subindex, "write", data)

    # ------------------------------------------------------------------- close

    def _shutdown(self) -> None:
        net, self.network = self.network, None
        if net is not None:
            try:
                net.nmt.send_command(layout.NMT_ENTER_PRE_OP)
            except Exception:  # closing a broken bus: nothing more to do
                pass
            net.disconnect()
        cyc, self._cyc = self._cyc, None
        if cyc is not None:
            cyc.shutdown()

    def close(self) -> None:
        """NMT pre-operational to every node (PDOs stop), release both buses. Idempotent."""
        self.is_open = False
        self._shutdown()


def _fmt_map(entries: list[tuple[int, int, int]]) -> str:
    return "[" + ", ".join(f"0x{i:04X}:{s:02X}/{b}" for i, s, b in entries) + "]"
