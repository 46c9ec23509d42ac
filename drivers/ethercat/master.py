"""EtherCAT master on pysoem (SOEM) implementing :class:`drivers.transport.Transport`.

Start-up (:meth:`EtherCATTransport.open`, blocking, raises errors that name the interface,
the slave and the values involved):

1. open the interface (must exist; raw sockets need root or CAP_NET_RAW);
2. scan (``config_init``): the slave count must equal the configured drive devices (one per
   drive, or one per multi-axis drive: ``bus.drives[i].device`` / ``device_axis`` put several
   joints on one slave, axis k's CiA-402 objects at 0x6000 + 0x800·k), and each slave's SII
   identity (vendor id, product code, revision) must match its ``bus.drives[i]``. With
   ``positions`` (a commissioning check of part of a longer line) the devices are the
   slaves at those line positions, and the other slaves go to PRE-OP with the line and
   stay there (no process data: never SAFE-OP or OP, never enabled);
3. INIT -> PRE-OP; each drive configured as its profile says (``bus.drives[i].profile``,
   :mod:`drivers.cia402.profiles`; no profile: the built-in 0x1600/0x1A00 layout): start-up
   SDOs of INIT -> PRE-OP and PRE-OP -> SAFE-OP in their order (once per slave), the
   configurable PDOs written (count 0, entries, count), the assignment 0x1C12/0x1C13 written
   when it differs
   (fixed PDOs are only assigned, never written); then the assignment and every assigned
   mapping are READ BACK and the wire layout is built from what the drive reports
   (:class:`drivers.cia402.wire.WireImage`): a difference from the profile is a one-line
   refusal naming the slave, the object, the expected and the found value;
   ``config_map`` builds the process image and its sizes are checked against the layout;
4. DC: ``config_dc`` and, per slave, SYNC0 (and SYNC1) as its profile's ``dc`` says (cycle:
   the profile's, else the loop period; shift), or at the loop period for every slave with
   ``bus.ethercat.dc_sync``; AssignActivate's low byte into ESC register 0x0980 where the
   profile asks for one (SOEM writes 0x00 there), read back (:mod:`drivers.ethercat.registers`);
5. SAFE-OP (then the SAFE-OP -> OP start-up SDOs), then OP while exchanging process data,
   checking states on the way; a slave that refuses is reported with its AL status code in
   words.

Start-up waits for states, never for a fixed time: every state change is polled until
``state_timeout``; mailbox traffic (SDOs, the watchdog register) that fails for lack of an
answer (WkcError, MailboxError, PacketError: a lost or late frame on a busy machine) is
retried ``mailbox_retries`` times with a short pause, as SOEM's users do; an SDO *abort* is
the drive's answer and is never retried. After an SDO transfer that got no valid answer the
slave's mailbox is brought back in step before the next transfer (SOEM matches an answer by
index, not subindex: a late answer must not pass for another subindex's;
:mod:`drivers.ethercat.mailbox`). A slave whose SM watchdog expired while the master
was late (SAFE-OP + ERROR, 0x001B) is acknowledged and requested to OP again.

Every cycle (:meth:`EtherCATTransport.exchange`): copy ``rx`` into the slaves' outputs, send
the process-data frame, receive it and compare the working counter with the expected one;
a lost frame or a short WKC is reported in the same cycle as a status code (``tx`` then
keeps the last good values). pysoem's API hands process data over as ``bytes``, so a cycle
makes one small ``bytes`` object per slave and direction; nothing else is allocated.

Outside the cycle: :meth:`check_bus` reads every slave's AL state and says in words what is
wrong (lost slave, SAFE-OP + ERROR with its AL status code), :meth:`recover_slaves` brings
them back when they answer again (a slave that was reset or lost power is configured by
the start's own steps: start-up SDOs, PDOs read back, DC; or kept out of OP, named),
:meth:`drive_faults` reads 0x603F of faulted drives.
"""

from __future__ import annotations

import os
import sys
import time
from collections import deque
from collections.abc import Sequence
from typing import Any

import numpy as np

from drivers.cia402 import pdo
from drivers.cia402.codes import describe_error_code
from drivers.ethercat.al_status import (
    STATE_NAMES,
    STATE_OP,
    STATE_PREOP,
    STATE_SAFEOP,
    describe_al_status_code,
    describe_state,
)
from drivers.ethercat.errors import (
    EtherCATError,
    IdentityMismatchError,
    RegisterMismatchError,
    SlaveLostError,
    SlavePositionError,
    StateChangeError,
)
from drivers.transport import (
    STATUS_BUS_ERROR,
    STATUS_NO_RESPONSE,
    STATUS_NOT_OPEN,
    STATUS_OK,
    STATUS_WKC_MISMATCH,
    SdoAbortError,
    Transport,
    TransportError,
)

_STATE_ACK = 0x10
_FAULT_BIT = 0x0008  # CiA 402 statusword bit 3
_AL_SM_WATCHDOG = 0x001B
_RETRY_PAUSE = 0.01  # [s] between mailbox retries: lets a late answer drain first


def _describe_exc(exc: BaseException) -> str:
    """pysoem's description of ``exc`` (its ``desc`` property can itself raise for an
    unknown code), else the exception's name."""
    try:
        desc = getattr(exc, "desc", "")
    except Exception:  # PacketError.desc looks the code up in a dict
        desc = f"code {getattr(exc, 'error_code', '?')}"
    return str(desc or type(exc).__name__)


def _pysoem() -> Any:
    import pysoem

    return pysoem


#: what SOEM's dc_sync writes to ESC register 0x0980 (AssignActivate's low byte)
SOEM_CYCLIC_UNIT_CONTROL = 0x00


class EtherCATTransport(Transport):
    """CiA-402 drives on EtherCAT through pysoem (see the module docstring).

    ``drives``: one :class:`hofto_hw.config.drives.DriveConfig` per slave, in line order
    (their ``identity`` is checked against the SII). ``dc_sync``: program SYNC0 at
    ``cycle_time``. ``recover``: :meth:`recover_slaves` may bring lost slaves back (else a
    lost slave stops the transport). ``receive_timeout`` [s]: how long ``exchange`` waits
    for its frame (default: one cycle). ``state_timeout`` [s]: per AL state change.
    ``mailbox_retries``: extra attempts of an SDO or register access that got no answer.
    ``sdo_timeout`` [s]: how long an SDO transfer waits for its answer (None: SOEM's 700 ms); a
    transfer that got no valid answer brings the slave's mailbox back in step before the
    next one (:mod:`drivers.ethercat.mailbox`). ``pdo_watchdog`` [s]: SM (process-data)
    watchdog written to every slave before SAFE-OP (None keeps the slave's default,
    typically 100 ms). ``positions``: the 1-based line
    position of each drive device, in device order, when the transport runs only part of a
    longer line (a commissioning check of some drives); the other slaves are brought to
    PRE-OP with the line (SOEM's mapping reads their PDOs by CoE) and left there: no process
    data, never SAFE-OP or OP, never enabled. None: the line has exactly the configured
    devices.
    """

    def __init__(
        self,
        interface: str,
        drives: Sequence[Any],
        cycle_time: float = 0.001,
        axis_names: list[str] | None = None,
        *,
        dc_sync: bool = False,
        profiles: Sequence[Any] | None = None,
        recover: bool = False,
        receive_timeout: float | None = None,
        state_timeout: float = 3.0,
        mailbox_retries: int = 3,
        pdo_watchdog: float | None = None,
        positions: Sequence[int] | None = None,
        sdo_timeout: float | None = None,
    ) -> None:
        super().__init__(len(drives), cycle_time, axis_names)
        self.interface = interface
        self.drives = list(drives)
        from drivers.cia402.profiles import builtin_profile

        #: one DriveProfile per slave (None in the list: the built-in layout)
        self.profiles = [
            p if p is not None else builtin_profile("ethercat")
            for p in (profiles if profiles is not None else [None] * len(self.drives))
        ]
        if len(self.profiles) != len(self.drives):
            raise ValueError(f"{len(self.profiles)} profiles for {len(self.drives)} drives")
        from drivers.cia402.profiles import refuse_unknown_units

        refuse_unknown_units(self.axis_names, self.profiles)
        self.use_fallbacks(self.profiles)
        from hofto_hw.config.drives import device_map

        #: (slave, CiA-402 axis of that slave) per axis: several axes may share a multi-axis
        #: drive (``bus.drives[i].device`` / ``device_axis``)
        self.serve = device_map(self.drives)
        self.n_devices = max(d for d, _k in self.serve) + 1
        #: the first axis on each slave (its configuration goes through it)
        devices = [d for d, _k in self.serve]
        self._first = [devices.index(d) for d in range(self.n_devices)]
        #: slaves whose axes are named with their axis number in messages
        self._multi = [
            devices.count(d) > 1 or self.profiles[self._first[d]].axes > 1
            for d in range(self.n_devices)
        ]
        #: SDO index shift of each axis's CiA-402 objects (0x800 per device axis)
        self._shift = [0x800 * k for _d, k in self.serve]
        if positions is not None:
            positions = [int(p) for p in positions]
            if len(positions) != self.n_devices or len(set(positions)) != len(positions):
                raise ValueError(
                    f"positions {positions}: one distinct line position per drive device "
                    f"({self.n_devices})"
                )
            if min(positions) < 1:
                raise ValueError(f"positions {positions}: line positions start at 1")
        #: 1-based line position of each device (None: device d is slave d + 1, whole line)
        self.positions = positions
        #: the slave at each 0-based line position -> its device (the devices run here)
        self._device_at = {
            (p - 1 if positions is not None else d): d
            for d, p in enumerate(positions if positions is not None else range(self.n_devices))
        }
        self._line: list[Any] = []  # every slave of the line (self.slaves: the devices')
        self._partial = False  # the line has slaves this transport leaves in PRE-OP
        self._raw_sdo = False  # device-level access (start-up, PDOs): no index shift
        self.dc_opt = dc_sync
        #: DC runs when asked for or when any drive's profile programs it
        self.dc_sync = dc_sync or any(p.dc is not None for p in self.profiles)
        #: start-up SDOs written at the last open (for commissioning reports)
        self.startup_written = 0
        #: one-line warnings of the last open (also printed on stderr once)
        self.warnings: list[str] = []
        self._cycle_ns = max(1, round(cycle_time * 1e9))
        self._dc_prev = -1  # DC system time of the last good exchange [ns]; -1: none
        self.recover = recover
        self.state_timeout = state_timeout
        self.mailbox_retries = max(0, int(mailbox_retries))
        self.pdo_watchdog = pdo_watchdog
        if sdo_timeout is not None and not 0.0 < sdo_timeout <= 10.0:
            raise ValueError(f"sdo_timeout {sdo_timeout} s not in (0, 10]")
        #: how long an SDO transfer waits for the drive's answer [s] (None: SOEM's 0.7 s)
        self.sdo_timeout = sdo_timeout
        #: mailbox accesses that needed a retry (start-up and SDO), for diagnostics
        self.mailbox_retried = 0
        #: device -> object of its last SDO transfer that got no valid answer: its mailbox is
        #: brought back in step before the next transfer (:meth:`_resync`)
        self._out_of_step: dict[int, int] = {}
        #: mailbox resynchronisations done (diagnostics, tests)
        self.mailbox_resynced = 0
        #: device -> why its reconfiguration after a loss failed (set by :meth:`_reconfigure`)
        self._not_reconfigured: dict[int, str] = {}
        timeout = cycle_time if receive_timeout is None else receive_timeout
        self._timeout_us = max(100, int(timeout * 1e6))
        self.master: Any = None
        self.slaves: list[Any] = []
        self.is_open = False
        self.stopped = False
        self.expected_wkc = 0
        self.last_wkc = 0
        self.cycles = 0
        self.lost_frames = 0
        self.wkc_errors = 0
        self._tx_rows: list[memoryview] = []
        self._rx_bounds: list[tuple[int, int]] = []
        self._set_rows(None)
        #: emergencies received (in mailbox reads), newest last: (axis, error code, register)
        self.emergencies: deque[tuple[int, int, int]] = deque(maxlen=64)

    @classmethod
    def from_config(
        cls,
        bus: Any,
        axis_names: list[str] | None = None,
        *,
        cycle_time: float,
        positions: Sequence[int] | None = None,
    ) -> EtherCATTransport:
        """From a :class:`hofto_hw.config.drives.BusConfig` with ``transport: ethercat``;
        ``cycle_time`` [s] is the system config's ``cycle_time`` (1 / loop.rate_hz);
        ``positions``: the line positions of the drives (a part of a longer line)."""
        opts = getattr(bus, "ethercat", None)
        kw: dict[str, Any] = {}
        if opts is not None:
            kw = {
                "dc_sync": opts.dc_sync,
                "recover": opts.recover_lost_slaves,
                "receive_timeout": opts.receive_timeout,
                "state_timeout": opts.state_timeout,
            }
            for name in ("mailbox_retries", "pdo_watchdog"):
                if getattr(opts, name, None) is not None:
                    kw[name] = getattr(opts, name)
        from drivers.cia402.profiles import profiles_for

        kw["profiles"] = profiles_for(bus.drives, "ethercat")
        return cls(bus.interface, bus.drives, cycle_time, axis_names, positions=positions, **kw)

    @property
    def line_slaves(self) -> int:
        """Slaves found on the line at the last open (0 before)."""
        return len(self._line)

    @property
    def left_alone(self) -> list[int]:
        """1-based line positions of the slaves this transport leaves in PRE-OP."""
        return [p + 1 for p in range(len(self._line)) if self._device_of(p) < 0]

    def _set_rows(self, wire: Any) -> None:
        """Byte views the cycle copies through: the canonical records themselves when every
        drive runs the built-in layout, else the wire image's per-slave slices."""
        self.wire = wire
        self._direct = wire is None or wire.builtin
        if self._direct:
            rs, ts = pdo.RXPDO_SIZE, pdo.TXPDO_SIZE
            tx_bytes = memoryview(self.tx.view(np.uint8))
            n = self.n_axes
            self._tx_rows = [tx_bytes[i * ts : (i + 1) * ts] for i in range(n)]
            self._rx_bounds = [(i * rs, (i + 1) * rs) for i in range(n)]
        else:
            tx_bytes = memoryview(wire.tx_in)
            off = wire.tx_offsets
            n = wire.n_devices
            self._tx_rows = [tx_bytes[off[i] : off[i + 1]] for i in range(n)]
            ro = wire.rx_offsets
            self._rx_bounds = [(int(ro[i]), int(ro[i + 1])) for i in range(n)]
        self._sizes = [
            (b - a, len(t)) for (a, b), t in zip(self._rx_bounds, self._tx_rows, strict=True)
        ]

    # -------------------------------------------------------------------- start-up

    def _who(self, axis: int) -> str:
        d, k = self.serve[axis]
        on = f" axis {k}" if self._multi[d] else ""
        return f"slave {d + 1}{on} ({self.axis_names[axis]}) on {self.interface}"

    def _who_slave(self, d: int) -> str:
        """Device ``d`` (0-based) by its line position, with the axes it drives."""
        if not 0 <= d < self.n_devices:
            return f"slave {d + 1} on {self.interface}"
        names = [self.axis_names[i] for i, (dev, _k) in enumerate(self.serve) if dev == d]
        return f"slave {self._position(d)} ({', '.join(names)}) on {self.interface}"

    def _position(self, d: int) -> int:
        """1-based line position of device ``d``."""
        return self.positions[d] if self.positions is not None else d + 1

    def _device_of(self, line_pos: int) -> int:
        """The device at 0-based line position ``line_pos`` (pysoem's numbering in
        callbacks, minus one); -1 for a slave this transport leaves alone."""
        return self._device_at.get(line_pos, -1)

    def _who_at(self, line_pos: int) -> str:
        """The slave at 0-based line position ``line_pos``, in words."""
        d = self._device_of(line_pos)
        if d >= 0:
            return self._who_slave(d)
        return f"slave {line_pos + 1} on {self.interface} (not run here)"

    def open(self) -> None:
        """Bring every slave to OP (steps in the module docstring); raises EtherCATError."""
        if self.is_open:
            return
        pysoem = _pysoem()
        if not os.path.exists(f"/sys/class/net/{self.interface}"):
            raise EtherCATError(
                f"bus.interface: network interface {self.interface!r} does not exist "
                "(see `ip link`)"
            )
        master = pysoem.Master()
        try:
            master.open(self.interface)
        except ConnectionError:
            raise EtherCATError(
                f"cannot open EtherCAT interface {self.interface!r}: raw sockets need root or "
                "CAP_NET_RAW"
            ) from None
        self.master = master
        if self.sdo_timeout is not None:
            us = round(self.sdo_timeout * 1e6)
            master.sdo_read_timeout = us
            master.sdo_write_timeout = us
        self._out_of_step = {}
        self.warnings = []
        try:
            self._start(pysoem)
        except BaseException:
            self._shutdown()
            raise
        for note in self.warnings:
            print(f"hofto-hw: warning: {note}", file=sys.stderr)
        self.is_open = True
        self.stopped = False

    def _start(self, pysoem: Any) -> None:
        m = self.master
        m.manual_state_change = 1
        # A scan whose frames got no answer (a link still coming up, a late emulator) finds
        # no slave, or a slave whose SII read timed out (vendor id 0 is no ETG identity):
        # scan again until state_timeout, as a state wait.
        deadline = time.monotonic() + self.state_timeout
        found = m.config_init()
        while (found <= 0 or any(s.man == 0 for s in m.slaves)) and (time.monotonic() < deadline):
            time.sleep(_RETRY_PAUSE)
            found = m.config_init()
        if found <= 0:
            raise EtherCATError(f"no EtherCAT slave answered on {self.interface}")
        self._line = list(m.slaves)
        if self.positions is not None:
            beyond = [p for p in self.positions if p > found]
            if beyond:
                raise SlavePositionError(
                    f"{self.interface}: slave position {beyond[0]} is beyond the EtherCAT line "
                    f"(found {found} slaves: positions 1 to {found})"
                )
            self.slaves = [self._line[p - 1] for p in self.positions]
            self._partial = found > self.n_devices
        elif found != self.n_devices:
            has = f"{self.n_devices} drives (bus.drives)"
            if self.n_devices != self.n_axes:
                has = f"{self.n_devices} drive devices for {self.n_axes} axes (bus.drives)"
            raise EtherCATError(
                f"{self.interface}: found {found} EtherCAT slaves, the config has {has}"
            )
        else:
            self.slaves = list(self._line)
        self._check_identities()
        for s in self.slaves:
            s.add_emergency_callback(self._on_emergency)
        # the whole line: SOEM's config_map reads every slave's PDO assignment by CoE
        self._request(STATE_PREOP, line=True)
        from drivers.cia402.wire import WireImage

        self.startup_written = 0
        layouts = [self._configure_preop(d) for d in range(self.n_devices)]
        wire = WireImage(layouts, self.axis_names, self.serve)
        wire.bind_master(self.rx, self.tx)
        from drivers.cia402.profiles import csp_adapter

        wire.set_adapter(
            csp_adapter(self.profiles, self.cycle_time, [d.counts_per_rev for d in self.drives])
        )  # ip / pv drives
        self._set_rows(wire)
        if self.pdo_watchdog is not None:
            for s in self.slaves:
                s.config_func = self._set_watchdog
        self._resync_all()  # SOEM's config_map reads the PDO assignment by CoE itself
        try:
            m.config_map()
        except pysoem.ConfigMapError as exc:
            raise EtherCATError(
                f"{self.interface}: PDO mapping failed: "
                + "; ".join(self._describe_mailbox_error(e) for e in exc.error_list)
            ) from None
        except pysoem.SdoError as exc:
            raise self._sdo_error(exc, "write") from None
        for s in self.slaves:  # a lost device that comes back (reconfig) is configured again
            s.config_func = self._reconfigure
        self.expected_wkc = m.expected_wkc - sum(
            2 * (len(s.output) > 0) + (len(s.input) > 0)  # an LRW: 2 per write, 1 per read
            for s in self._line
            if all(s is not t for t in self.slaves)
        )  # slaves left in PRE-OP have their SMs off: the LRW does not count them
        for i, s in enumerate(self.slaves):
            sizes = (len(s.output), len(s.input))
            if sizes != self._sizes[i]:
                want = self._sizes[i]
                raise EtherCATError(
                    f"{self._who_slave(i)}: process data is {sizes[0]} bytes out / {sizes[1]} in, "
                    f"expected {want[0]} / {want[1]} (PDO mapping not applied)"
                )
        if self.dc_sync:
            if not m.config_dc():
                raise EtherCATError(f"{self.interface}: no slave supports distributed clocks")
            self._configure_dc(range(self.n_devices))
        self._dc_prev = -1
        self.sample_dt = 0.0
        if self.derived is not None:
            self.derived.reset()
        self._request(STATE_SAFEOP)
        for d in range(self.n_devices):
            self._configure_safeop(d)
        self.rx.fill(0)
        self._request(STATE_OP, cyclic=True)

    def _check_identities(self) -> None:
        for i, d in enumerate(self.drives):
            s = self.slaves[self.serve[i][0]]
            ident = d.identity
            checks = [
                ("vendor id", ident.vendor_id, s.man),
                ("product code", ident.product_code, s.id),
            ]
            if ident.revision is not None:
                checks.append(("revision", ident.revision, s.rev))
            for what, want, got in checks:
                if got != want:
                    raise IdentityMismatchError(
                        f"bus.drives[{i}].identity: {self._who(i)} ('{s.name}') has {what} "
                        f"0x{got:08X}, expected 0x{want:08X}",
                        i + 1,
                        what,
                        want,
                        got,
                    )

    def _axis_of_slave(self, d: int) -> int:
        """The first axis on slave ``d`` (0-based); 0 for a position off the bus."""
        return self._first[d] if 0 <= d < self.n_devices else 0

    # What a device needs before each transition: one path for the start and for a device
    # brought back by recover_slaves (a power cycle loses start-up values, PDOs, DC).

    def _configure_preop(self, d: int) -> Any:
        """In PRE-OP, device ``d``: its INIT -> PRE-OP and PRE-OP -> SAFE-OP start-up SDOs,
        then its PDOs written, assigned and read back; returns the layout it reports."""
        self._startup(self._first[d], ("IP", "PS"))
        return self._configure_pdos(self._first[d])

    def _configure_dc(self, devices: Any) -> None:
        """In PRE-OP, after ``config_dc``: SYNC0/SYNC1 and AssignActivate's 0x0980 of
        ``devices`` (0-based) as their profiles say."""
        for d in devices:
            self._program_dc(self._first[d], self.slaves[d])
        self._program_cyclic_units(devices)

    def _configure_safeop(self, d: int) -> None:
        """In SAFE-OP, device ``d``: its SAFE-OP -> OP start-up SDOs."""
        self._startup(self._first[d], ("SO",))

    def _startup(self, axis: int, transitions: tuple[str, ...]) -> None:
        """Write the profile's start-up SDOs of ``transitions`` to the slave of ``axis``, in
        the profile's order (indices as the profile gives them: device level)."""
        from drivers.cia402.profiles import write_startup

        self._raw_sdo = True
        try:
            self.startup_written += write_startup(self, axis, self.profiles[axis], transitions)
        finally:
            self._raw_sdo = False

    def _configure_pdos(self, axis: int) -> Any:
        """The profile's PDOs written, assigned and read back on the slave of ``axis``: the
        layout the drive reports (:func:`drivers.cia402.profiles.configure_pdos`; a
        difference: EtherCATError)."""
        from drivers.cia402.profiles import configure_pdos

        self._raw_sdo = True
        try:
            return configure_pdos(self, axis, self.profiles[axis], EtherCATError)
        finally:
            self._raw_sdo = False

    def _program_dc(self, axis: int, slave: Any) -> None:
        """SYNC0 (and SYNC1) of one slave as its profile says; without a ``dc`` section the
        slave runs free unless ``bus.ethercat.dc_sync`` asks for SYNC0 at the loop period.

        pysoem's ``dc_sync`` (SOEM's ecx_dcsync0 / ecx_dcsync01) writes the activation
        register 0x0981 (AssignActivate's high byte: 0x03 SYNC0, 0x07 SYNC0 + SYNC1) and
        always 0x00 to 0x0980 (AssignActivate's low byte); :meth:`_program_cyclic_units`
        then writes the low byte the profile asks for."""
        dc = self.profiles[axis].dc
        if dc is None:
            if self.dc_opt:
                slave.dc_sync(True, self._cycle_ns)
            return
        cycle = dc.sync0_cycle_ns or self._cycle_ns
        if (dc.assign_activate >> 8) & 0x04 and dc.sync1_cycle_ns is not None:
            slave.dc_sync(True, cycle, dc.sync0_shift_ns, dc.sync1_cycle_ns)
        else:
            slave.dc_sync(True, cycle, dc.sync0_shift_ns)

    def _program_cyclic_units(self, devices: Any) -> None:
        """AssignActivate's low byte into ESC register 0x0980 (cyclic unit control: SYNC
        out and latch units to the drive's PDI, e.g. Nanotec's 0x0330 -> 0x30) for each
        of ``devices`` whose profile asks for another value than the 0x00 SOEM's ``dc_sync``
        writes, then read back: a difference is refused in one line naming the slave, the
        register, the expected and the found value (a drive needing it refuses SAFE-OP
        with AL status 0x0030 otherwise). pysoem has no public register write, so the
        datagrams go out on a socket of our own (:mod:`drivers.ethercat.registers`), here,
        after dc_sync and before the SAFE-OP request, when SOEM has no frame in flight."""
        todo = []
        for d in devices:
            dc = self.profiles[self._first[d]].dc
            if dc is not None and dc.assign_activate & 0xFF != SOEM_CYCLIC_UNIT_CONTROL:
                todo.append((d, dc.assign_activate))
        if not todo:
            return
        from drivers.ethercat.registers import CYCLIC_UNIT_CONTROL, RegisterPort

        attempts = self.mailbox_retries + 1
        with RegisterPort(self.interface, timeout=0.1, attempts=attempts) as port:
            for d, assign in todo:
                who = self._who_slave(d)
                want = assign & 0xFF
                station = port.station_address(self._position(d), who)
                port.write(station, CYCLIC_UNIT_CONTROL, bytes([want]), who)
                found = port.read(station, CYCLIC_UNIT_CONTROL, 1, who)[0]
                if found != want:
                    raise RegisterMismatchError(
                        f"{who}: ESC register 0x0980 (cyclic unit control, AssignActivate "
                        f"0x{assign:04X} of profile {self.profiles[self._first[d]].name}) "
                        f"reads back 0x{found:02X}, expected 0x{want:02X}"
                    )

    def _reconfigure(self, pos: int) -> None:
        """PRE-OP -> SAFE-OP hook of a slave brought back by :meth:`recover_slaves` (SOEM's
        reconfig calls it in PRE-OP, then asks for SAFE-OP): what the start did before
        SAFE-OP, by the same methods: start-up SDOs and PDOs (the layout checked against
        the one the bus runs with), the SM watchdog, DC (SYNC0/SYNC1, 0x0980). Its DC
        system-time offset is not written again (pysoem's config_dc is line-wide and would
        move the running slaves' time): SYNC0 starts on the slave's own clock. pysoem keeps
        an exception raised here to itself: it is noted for recover_slaves, which then
        keeps the slave out of OP and says why."""
        d = self._device_of(pos)  # pysoem passes the 0-based line position
        try:
            layout = self._configure_preop(d)
            if self.wire is not None and layout != self.wire.layouts[d]:
                raise EtherCATError(f"{self._who_slave(d)}: came back with another PDO layout")
            if self.pdo_watchdog is not None:
                self._set_watchdog(pos)
            if self.dc_sync:
                self._configure_dc([d])
        except Exception as exc:
            self._not_reconfigured[d] = str(exc) or type(exc).__name__
            raise
        self._not_reconfigured.pop(d, None)

    def _set_watchdog(self, pos: int) -> None:
        """PRE-OP -> SAFE-OP hook: the SM watchdog time (``pdo_watchdog``)."""
        d = self._device_of(pos)  # pysoem passes the 0-based line position
        s = self.slaves[d]
        ms = self.pdo_watchdog * 1000.0
        self._retry(lambda: s.set_watchdog("processdata", ms), self._first[d], "SM watchdog write")

    def _retry(self, fn: Any, axis: int, what: str) -> Any:
        """Call ``fn`` again when the mailbox/register access got no (valid) answer.

        WkcError (no answer in time), MailboxError and PacketError (a late or unexpected
        mailbox frame) are transient on a busy machine: SOEM users retry them after a short
        pause. SdoError (an abort: the drive's answer) propagates at once. After the last
        attempt an EtherCATError names the slave and the access.
        """
        pysoem = _pysoem()
        transient = (pysoem.WkcError, pysoem.MailboxError, pysoem.PacketError)
        for attempt in range(self.mailbox_retries + 1):
            try:
                return fn()
            except transient as exc:
                if attempt == self.mailbox_retries:
                    raise EtherCATError(
                        f"{self._who(axis)}: {what} failed after {attempt + 1} attempts: "
                        f"{_describe_exc(exc)}"
                    ) from None
                self.mailbox_retried += 1
                time.sleep(_RETRY_PAUSE)
        raise AssertionError("unreachable")

    def _request(self, state: int, cyclic: bool = False, line: bool = False) -> None:
        """Request ``state`` on the drive devices (``line``: on every slave of the line) and
        wait; raises StateChangeError in words. With slaves left alone on the line, each
        device is requested and checked on its own (SOEM's master-wide request and check
        would take the others along)."""
        m = self.master
        partial = self._partial and not line
        slaves = self.slaves if partial else self._line
        if partial:
            for s in slaves:
                s.state = state
                s.write_state()
        else:
            m.state = state
            m.write_state()
        deadline = time.monotonic() + self.state_timeout
        timeout_us = 1000 if cyclic else 50_000
        while time.monotonic() < deadline:
            if cyclic:
                self._raw_exchange()
            if partial:
                if all(s.state_check(state, timeout_us) == state for s in slaves):
                    return
            elif m.state_check(state, timeout_us) == state:
                return
            m.read_state()
            if cyclic and self._ack_watchdog_errors(state):
                continue  # the master was late, not the slave wrong: ask again
            if any(s.state & 0x10 for s in slaves):
                break  # a slave refused with an error: no point waiting
            if cyclic:
                time.sleep(self.cycle_time)
        m.read_state()
        problems = {
            i + 1: (s.state, s.al_status)
            for i, s in enumerate(self._line)
            if s.state != state and any(s is t for t in slaves)
        }
        target = STATE_NAMES.get(state, hex(state))
        parts = []
        for slave, (st, code) in problems.items():
            who = self._who_at(slave - 1)
            if st == 0:
                parts.append(f"{who} does not answer")
            else:
                parts.append(
                    f"{who} is in {describe_state(st)}, AL status {describe_al_status_code(code)}"
                )
        raise StateChangeError(
            f"EtherCAT slaves did not reach {target}: " + "; ".join(parts or ["timeout"]),
            problems,
        )

    def _ack_watchdog_errors(self, state: int) -> bool:
        """Acknowledge slaves in SAFE-OP + ERROR with an expired SM watchdog (0x001B) and
        request ``state`` again; True if any was. Other AL errors are real refusals."""
        acked = False
        for s in self.slaves:
            if s.state == STATE_SAFEOP | _STATE_ACK and s.al_status == _AL_SM_WATCHDOG:
                s.state = STATE_SAFEOP | _STATE_ACK
                s.write_state()
                s.state = state
                s.write_state()
                acked = True
        return acked

    # ------------------------------------------------------------------- the cycle

    def _raw_exchange(self) -> int:
        m = self.master
        if self._direct:
            raw = self.rx.tobytes()
        else:
            self.wire.encode_rx()
            raw = self.wire.rx_out.tobytes()
        for (a, b), s in zip(self._rx_bounds, self.slaves, strict=False):
            s.output = raw[a:b]
        m.send_processdata()
        return m.receive_processdata(self._timeout_us)

    def exchange(self) -> int:
        """One cycle: outputs out, inputs in, WKC checked. Returns a status; never raises."""
        # until a good frame says otherwise: no new sample (the next good frame's DC time
        # spans the gap), or unknown without DC
        self.sample_dt = -1.0 if self.dc_sync and self._dc_prev >= 0 else 0.0
        if not self.is_open:
            return STATUS_NOT_OPEN
        if self.stopped:
            return STATUS_BUS_ERROR
        self.cycles += 1
        try:
            wkc = self._raw_exchange()
        except Exception:
            return STATUS_BUS_ERROR
        self.last_wkc = wkc
        if wkc < 0:
            self.lost_frames += 1
            return STATUS_NO_RESPONSE
        if wkc != self.expected_wkc:
            self.wkc_errors += 1
            return STATUS_WKC_MISMATCH
        for row, s in zip(self._tx_rows, self.slaves, strict=False):
            row[:] = s.input
        if not self._direct:
            self.wire.decode_tx()
        if self.dc_sync:
            self._sample_interval(self.master.dc_time)
        if self.derived is not None:
            self.derived.apply(self.sample_dt)
        return STATUS_OK

    def _sample_interval(self, dc_now: int) -> None:
        """Set :attr:`sample_dt` from the reference clock's system time ``dc_now`` [ns] (read
        in this cycle's frame). The drives latch their inputs at SYNC0, on the multiples of
        the cycle in DC time, so the samples moved by the whole cycles between the two
        frames (at least one: a frame within the same cycle repeats nothing new)."""
        prev, cyc = self._dc_prev, self._cycle_ns
        self._dc_prev = dc_now
        if prev < 0 or dc_now <= prev:
            self.sample_dt = 0.0
            return
        self.sample_dt = max(1, dc_now // cyc - prev // cyc) * self.cycle_time

    # ------------------------------------------------------------- supervision

    def check_bus(self) -> list[str]:
        """Read every slave's AL state; one plain-word line per slave that is not in OP."""
        if self.master is None:
            return [f"EtherCAT master on {self.interface} is not open"]
        self.master.read_state()
        out = []
        for i, s in enumerate(self.slaves):
            if s.state == STATE_OP:
                continue
            if s.state == 0:
                out.append(f"{self._who_slave(i)} does not answer (lost)")
            else:
                out.append(
                    f"{self._who_slave(i)} is in {describe_state(s.state)}, AL status "
                    f"{describe_al_status_code(s.al_status)}"
                )
        return out

    def recover_slaves(self) -> list[str]:
        """Bring slaves that are not in OP back to OP; returns what was done, in words (one
        line each).

        A lost slave (reset or powered off and back: INIT, no station address) is
        re-addressed once it answers and configured again as at the start, by the same
        methods (:meth:`_reconfigure`: start-up SDOs, PDOs checked against the running
        layout, SM watchdog, DC; then the SAFE-OP -> OP start-up SDOs); one that cannot be
        is left out of OP, named with the reason. A slave in an error state is acknowledged
        and requested to OP. Without ``recover`` the transport stops instead and
        :class:`SlaveLostError` is raised.
        """
        problems = self.check_bus()
        if not problems:
            return []
        if not self.recover:
            self.stopped = True
            raise SlaveLostError("EtherCAT bus stopped: " + "; ".join(problems))
        done = []
        pysoem = _pysoem()
        refused: set[int] = set()
        for i, s in enumerate(self.slaves):
            if s.state == STATE_OP:
                continue
            if s.state == 0:
                if not self._until(lambda s=s: s.recover(20_000) > 0):
                    done.append(f"{self._who_slave(i)} still does not answer")
                    refused.add(i)
                    continue
                self._out_of_step.pop(i, None)  # a reset slave's mailbox starts empty
                self._not_reconfigured[i] = "it did not reach PRE-OP to be configured"
                self._until(lambda s=s: s.reconfig(50_000) >= STATE_PREOP)
                why = self._not_reconfigured.pop(i, None)
                if why is None and s.state == STATE_SAFEOP:
                    try:
                        self._configure_safeop(i)
                    except TransportError as exc:  # an SDO abort, a mailbox out of step
                        why = str(exc)
                if why is not None:  # never OP with what the start would have refused
                    s.state = STATE_PREOP
                    s.write_state()
                    refused.add(i)
                    done.append(f"{self._who_slave(i)} answered again but stays out of OP: {why}")
                    continue
                done.append(f"{self._who_slave(i)} answered again and was reconfigured")
            elif s.state & 0x10:
                s.state = (s.state & 0x0F) | _STATE_ACK
                s.write_state()
                done.append(
                    f"{self._who_slave(i)}: acknowledged AL status "
                    f"{describe_al_status_code(s.al_status)}"
                )
            if s.state & 0x0F == STATE_SAFEOP or s.state & 0x10:
                s.state = pysoem.OP_STATE
                s.write_state()
        wanted = [s for i, s in enumerate(self.slaves) if i not in refused]
        deadline = time.monotonic() + self.state_timeout
        while time.monotonic() < deadline:
            self._raw_exchange()
            if all(s.state_check(STATE_OP, 1000) == STATE_OP for s in wanted):
                break
            self.master.read_state()
            self._ack_watchdog_errors(STATE_OP)
            time.sleep(self.cycle_time)
        remaining = self.check_bus()
        return done + remaining

    def _until(self, attempt: Any) -> bool:
        """Repeat ``attempt()`` (a short SOEM call with its own timeout) until it returns
        True or ``state_timeout`` has passed."""
        deadline = time.monotonic() + self.state_timeout
        while True:
            if attempt():
                return True
            if time.monotonic() >= deadline:
                return False
            time.sleep(_RETRY_PAUSE)

    def drive_faults(self) -> list[str]:
        """Axes whose statusword shows Fault, with 0x603F read by SDO and decoded."""
        out = []
        for i in np.flatnonzero(self.tx["statusword"] & _FAULT_BIT):
            axis = int(i)
            try:
                code = self.read_value(axis, 0x603F, 0, "u16")
            except TransportError as exc:  # SdoAbortError, EtherCATError (mailbox), short data
                out.append(f"{self._who(axis)}: fault, error code unreadable ({exc})")
                continue
            out.append(f"{self._who(axis)}: drive fault {describe_error_code(code)}")
        return out

    def _on_emergency(self, emcy: Any) -> None:
        self.emergencies.append(
            (
                self._axis_of_slave(self._device_of(int(emcy.slave_pos) - 1)),
                int(emcy.error_code),
                int(emcy.error_reg),
            )
        )

    def emergency_messages(self) -> list[str]:
        """Emergency messages received so far, in words (oldest first)."""
        return [
            f"{self._who(a)}: emergency {describe_error_code(code)}, error register 0x{reg:02X}"
            for a, code, reg in self.emergencies
            if 0 <= a < self.n_axes
        ]

    # ----------------------------------------------------------------------- SDO

    def _describe_mailbox_error(self, exc: Any) -> str:
        pysoem = _pysoem()
        if isinstance(exc, pysoem.SdoError):
            return str(self._sdo_error(exc, "access"))
        pos = int(getattr(exc, "slave_pos", 0))
        who = self._who_at(pos - 1) if pos >= 1 else f"slave {pos}"
        desc = _describe_exc(exc)
        return f"{who}: {desc}"

    def _sdo_error(self, exc: Any, action: str) -> SdoAbortError:
        pos = int(getattr(exc, "slave_pos", 1))
        axis = self._axis_of_slave(self._device_of(pos - 1))
        return SdoAbortError(
            axis, exc.index, exc.subindex, exc.abort_code, action, self.axis_names[axis]
        )

    def sdo_read(self, axis: int, index: int, subindex: int) -> bytes:
        """Upload ``index:subindex`` of drive ``axis``; raises SdoAbortError/EtherCATError."""
        index = self._object(axis, index)
        return bytes(
            self._sdo(axis, index, subindex, "read", lambda s: s.sdo_read(index, subindex))
        )

    def _object(self, axis: int, index: int) -> int:
        """The slave's index of ``axis``'s object ``index``: a CiA-402 object (0x6000..0x67FF)
        of axis k of a multi-axis drive sits at index + 0x800·k (not for the device-level
        start-up and PDO configuration, which name their objects as the profile does)."""
        if not self._raw_sdo and 0x6000 <= index < 0x6800 and 0 <= axis < self.n_axes:
            return index + self._shift[axis]
        return index

    def sdo_write(self, axis: int, index: int, subindex: int, data: bytes) -> None:
        """Download ``data`` to ``index:subindex`` of drive ``axis``; raises SdoAbortError."""
        payload = bytes(data)
        index = self._object(axis, index)
        self._sdo(axis, index, subindex, "write", lambda s: s.sdo_write(index, subindex, payload))

    def _sdo(self, axis: int, index: int, subindex: int, action: str, call: Any) -> Any:
        """``call(slave)`` with mailbox retries; an SDO abort becomes SdoAbortError."""
        self._check_axis(axis)
        pysoem = _pysoem()
        if self.master is None:
            raise EtherCATError(f"EtherCAT master on {self.interface} is not open")
        d = self.serve[axis][0]
        slave = self.slaves[d]
        what = f"SDO {action} 0x{index:04X}:{subindex:02X}"
        transient = (pysoem.WkcError, pysoem.MailboxError, pysoem.PacketError)

        def attempt() -> Any:
            if d in self._out_of_step:
                self._resync(d, axis, what, index)
            try:
                return call(slave)
            except transient:
                self._out_of_step[d] = index  # its answer may still come: resync first
                raise

        try:
            return self._retry(attempt, axis, what)
        except pysoem.SdoError as exc:
            raise SdoAbortError(
                axis, index, subindex, exc.abort_code, action, self.axis_names[axis]
            ) from None

    def _resync(self, d: int, axis: int, what: str, index: int) -> None:
        """Bring device ``d``'s mailbox back in step before ``what`` is sent: a transfer to it
        got no valid answer, and its late answer must not be taken for the next one
        (:mod:`drivers.ethercat.mailbox`). Raises EtherCATError naming the slave, the failed
        transfer and the fence objects when none of them answers cleanly."""
        from drivers.ethercat.mailbox import fence_names, resync

        pysoem = _pysoem()
        errors = (pysoem.WkcError, pysoem.MailboxError, pysoem.PacketError, pysoem.SdoError)
        failed = self._out_of_step[d]
        s = self.slaves[d]
        if resync(lambda i, sub: s.sdo_read(i, sub), errors, failed) is None:
            raise EtherCATError(
                f"{self._who(axis)}: {what} not sent: mailbox out of step since an SDO transfer "
                f"of 0x{failed:04X} got no valid answer, and none of {fence_names(failed)} "
                "answered cleanly either"
            )
        del self._out_of_step[d]
        self.mailbox_resynced += 1

    def _resync_all(self) -> None:
        """Every device's mailbox in step (before SOEM's own CoE transfers: config_map)."""
        for d in list(self._out_of_step):
            self._resync(d, self._first[d], "PDO mapping", self._out_of_step[d])

    # ----------------------------------------------------------------------- close

    def _shutdown(self) -> None:
        m = self.master
        if m is None:
            return
        try:
            if self._partial:  # the slaves left alone stay in PRE-OP
                for s in self.slaves:
                    s.state = 1  # INIT
                    s.write_state()
            elif self.slaves:
                m.state = 1  # INIT
                m.write_state()
        except Exception:  # closing a broken bus: nothing more to do
            pass
        m.close()
        self.master = None

    def close(self) -> None:
        """Request INIT and close the interface. Safe to call twice."""
        self.is_open = False
        self._shutdown()
