"""A software EtherCAT slave controller (ESC): register space, SII, AL, SyncManagers, FMMUs.

:class:`Esc` is what one slave looks like to datagrams: ``read``/``write`` of its 64 KiB
physical address space (with the side effects of the real chip) and ``logical`` for
LRD/LWR/LRW through its FMMUs. Each access returns whether it was performed, which is
what the working counter counts. The slave application side (mailbox/CoE, AL state
machine decisions, the process-data copy to and from the emulated drive) runs synchronously
inside those calls or when the network asks (:meth:`Esc.pull_outputs`, :meth:`Esc.push_inputs`).

Behaviour follows the Beckhoff ESC datasheet section II and ETG.1000.4/.6 where SOEM relies
on it (see docs/ethercat_emulator.md for what is left out):
- SyncManager status (byte 5) and PDI-control (byte 7) cannot be written by the master, so
  SOEM's whole-block SM writes keep them;
- mailbox SMs: writing the last byte of the write mailbox makes it full (the request is
  processed at once and the mailbox emptied); reading the last byte of a full read mailbox
  empties it; reading an empty read mailbox or writing a full write mailbox is not performed
  (no WKC); repeat requests re-send the last reply;
- process-data SMs are deactivated by the slave below SAFE-OP (accesses not performed);
- AL control requests follow the ETG state machine with AL status codes and the error flag.
"""

from __future__ import annotations

import struct
import time
from collections import deque
from collections.abc import Callable, Sequence

import numpy as np

from drivers.cia402 import pdo
from drivers.sim.esc import pdo_map
from drivers.sim.esc import registers as r
from drivers.sim.esc.coe import COE_SDO_REQUEST, MBX_HEADER, MBX_TYPE_COE, CoeServer
from drivers.sim.esc.description import SlaveDescription
from drivers.sim.esc.sii import build_image
from drivers.sim.object_dictionary import ObjectDictionary

# AL status codes the emulator raises (ETG.1000.6 table 11).
AL_NO_ERROR = 0x0000
AL_INVALID_STATE_CHANGE = 0x0011
AL_UNKNOWN_STATE = 0x0012
AL_BOOTSTRAP_NOT_SUPPORTED = 0x0013
AL_INVALID_MBX_CONFIG = 0x0016
AL_INVALID_SM_CONFIG = 0x0017
AL_SM_WATCHDOG = 0x001B
AL_INVALID_DC_SYNC = 0x0030
AL_INVALID_OUTPUT_CONFIG = 0x001D
AL_INVALID_INPUT_CONFIG = 0x001E
AL_INVALID_DC_SYNC = 0x0030
AL_INVALID_SYNC_CYCLE = 0x0035

_VALID_STATES = (r.STATE_INIT, r.STATE_PREOP, r.STATE_BOOT, r.STATE_SAFEOP, r.STATE_OP)

# Transitions the state machine allows (from, to); anything else is 0x0011.
_ALLOWED = {
    (r.STATE_INIT, r.STATE_PREOP),
    (r.STATE_INIT, r.STATE_BOOT),
    (r.STATE_PREOP, r.STATE_SAFEOP),
    (r.STATE_SAFEOP, r.STATE_OP),
}


def _writable_mask() -> bytearray:
    """Register bytes (below 0x1000) the master may write."""
    m = bytearray(r.PROCESS_RAM)
    ranges = [
        (r.STATION_ADDRESS, 2),
        (r.DL_CONTROL, 4),
        (0x0108, 2),  # physical read/write offset
        (r.AL_CONTROL, 2),
        (0x0200, 2),  # ECAT event mask
        (r.RX_ERROR_COUNTERS, 0x14),
        (r.WATCHDOG_DIVIDER, 2),
        (r.WATCHDOG_TIME_PDI, 2),
        (r.WATCHDOG_TIME_PD, 2),
        (r.EEPROM_CONFIG, 1),
        (r.EEPROM_CONTROL, 2),
        (r.EEPROM_ADDRESS, 4),
        (r.EEPROM_DATA, 8),
        (r.FMMU_BASE, r.FMMU_SIZE * r.FMMU_COUNT),
        (r.DC_RECEIVE_TIME_PORT0, 4),
        (r.DC_SYSTEM_TIME_OFFSET, 8),
        (r.DC_SYSTEM_TIME_DELAY, 4),
        (0x0930, 2),  # speed counter start
        (0x0934, 2),  # system time difference filter depth
        (r.DC_CYCLIC_UNIT_CONTROL, 2),
        (r.DC_SYNC0_START, 8),
        (r.DC_SYNC0_CYCLE, 8),
    ]
    for start, length in ranges:
        m[start : start + length] = b"\x01" * length
    for k in range(r.SM_COUNT):
        base = r.SM_BASE + k * r.SM_SIZE
        m[base : base + 5] = b"\x01" * 5
        m[base + r.SM_ACTIVATE_OFFSET] = 1
    return m


_WRITABLE = _writable_mask()


def _sdo_request_object(frame: bytes) -> tuple[int, int] | None:
    """(index, subindex) of a CoE SDO upload or download request (its initiation), else None."""
    if len(frame) < MBX_HEADER + 6 or frame[5] & 0x0F != MBX_TYPE_COE:
        return None
    service = struct.unpack_from("<H", frame, MBX_HEADER)[0] >> 12
    if service != COE_SDO_REQUEST or frame[MBX_HEADER + 2] >> 5 not in (1, 2):
        return None
    index, sub = struct.unpack_from("<HB", frame, MBX_HEADER + 3)
    return index, sub


class Esc:
    """One emulated slave (see module docstring).

    ``od`` is the drive's object dictionary served over CoE (``None``: a slave without an
    application, for unit tests). ``position`` is the slave's place on the line (0-based)
    and ``n_slaves`` the line length (for the DL status port bits). ``clock`` returns the
    local time [ns] (the PDO watchdog's); ``dc_clock`` the DC local time [ns] (receive-time
    latches, system time 0x0910), ``clock`` when None: the network sets it to its drives'
    simulated time, so that the DC time advances with the samples as a drive's own clock does.
    """

    def __init__(
        self,
        desc: SlaveDescription,
        od: ObjectDictionary | None,
        position: int = 0,
        n_slaves: int = 1,
        clock: Callable[[], int] = time.monotonic_ns,
        dc_clock: Callable[[], int] | None = None,
        records: Sequence[int | None] | None = None,
    ) -> None:
        self.desc = desc
        self.od = od
        #: per CiA-402 axis of the device, the index of the drive record it exchanges with
        #: (:meth:`pull_outputs` / :meth:`push_inputs` then take the whole record array);
        #: None: one axis, the record itself
        self.records = list(records) if records is not None else None
        self.position = position
        self.clock = clock
        self.dc_clock = dc_clock if dc_clock is not None else clock
        self.mem = bytearray(r.ADDRESS_SPACE)
        self.mem_np = np.frombuffer(self.mem, dtype=np.uint8)
        self.sii = bytearray(build_image(desc))
        self.coe = CoeServer(od, desc.mbx_out_size, desc.mbx_in_size) if od is not None else None
        self.outbox: deque[bytes] = deque()
        self.last_reply = b""
        #: fault injection: requested state -> AL status code to refuse it with
        self.refuse: dict[int, int] = {}
        #: fault injection: the slave does not process datagrams (link down)
        self.silent = False
        #: fault injection: (index, subindex) -> how many answers to SDO requests of that
        #: object come late: such an answer is held until the master's next mailbox request
        #: (it has given up waiting by then) and goes out just before that request's own
        #: answer, in order, as a slow drive's does
        self.late: dict[tuple[int, int], int] = {}
        self._held: list[bytes] = []
        #: set when the master completed a write of the SM2 buffer (new outputs)
        self.outputs_fresh = False
        self.last_output_ns = 0
        self.output_plan: pdo_map.CopyPlan = ()
        self.input_plan: pdo_map.CopyPlan = ()
        self.sync0_active = False
        #: the highest AL state the slave has been in (tests: a slave left alone stays low)
        self.highest_state = r.STATE_INIT
        self._latched_ns = 0
        self._sms: list[tuple[int, int, int, int]] = []  # (k, start, end, control) enabled
        self._fmmus: list[tuple[int, int, int, int]] = []  # (log_start, log_end, phys, type)
        self._reset_registers(n_slaves)

    # ------------------------------------------------------------------ registers

    def _reset_registers(self, n_slaves: int) -> None:
        m = self.mem
        m[r.TYPE] = 0x98  # an ET1100-class ESC as type; only used for display
        m[r.REVISION] = 0x02
        m[r.FMMUS_SUPPORTED] = r.FMMU_COUNT
        m[r.SMS_SUPPORTED] = r.SM_COUNT
        m[r.RAM_SIZE] = 60  # KiB of process RAM
        m[r.PORT_DESCRIPTOR] = 0x0F  # ports 0 and 1 MII, 2 and 3 not implemented
        features = 0x000C if self.desc.dc_supported else 0x0000  # DC available, 64-bit
        struct.pack_into("<H", m, r.FEATURES, features)
        struct.pack_into("<H", m, r.STATION_ALIAS, self.desc.alias)
        last = self.position == n_slaves - 1
        dl = 0x0001 | 0x0010 | 0x0200 | 0x1000 | 0x4000  # PDI ok, port 0 link+comm, 2/3 closed
        dl |= 0x0400 if last else (0x0020 | 0x0800)  # port 1: closed, or link + comm
        struct.pack_into("<H", m, r.DL_STATUS, dl)
        struct.pack_into("<H", m, r.PDI_CONTROL, 0x0080)  # on-chip bus PDI
        struct.pack_into("<H", m, r.WATCHDOG_DIVIDER, 2498)  # 100 µs units
        struct.pack_into("<H", m, r.WATCHDOG_TIME_PD, round(self.desc.sm_watchdog_ms * 10))
        struct.pack_into("<H", m, r.EEPROM_CONTROL, r.EEPROM_READ_8_BYTES)
        self._set_al(r.STATE_INIT, AL_NO_ERROR, error=False)

    @property
    def station_address(self) -> int:
        """Configured station address (0x0010)."""
        return self.mem[r.STATION_ADDRESS] | (self.mem[r.STATION_ADDRESS + 1] << 8)

    @property
    def al_state(self) -> int:
        """AL status register low byte: state | 0x10 when the error flag is set."""
        return self.mem[r.AL_STATUS]

    @property
    def al_status_code(self) -> int:
        """AL status code (0x0134)."""
        return self.mem[r.AL_STATUS_CODE] | (self.mem[r.AL_STATUS_CODE + 1] << 8)

    def _set_al(self, state: int, code: int, error: bool) -> None:
        if state != r.STATE_BOOT:
            self.highest_state = max(getattr(self, "highest_state", r.STATE_INIT), state)
        self.mem[r.AL_STATUS] = state | (r.AL_ERROR_FLAG if error else 0)
        self.mem[r.AL_STATUS + 1] = 0
        struct.pack_into("<H", self.mem, r.AL_STATUS_CODE, code)
        if self.od is not None:
            self.od.pdo_locked = state in (r.STATE_SAFEOP, r.STATE_OP)
        mbx_on = state != r.STATE_INIT
        pd_on = state in (r.STATE_SAFEOP, r.STATE_OP)
        for k in range(r.SM_COUNT):
            pdi = r.SM_BASE + k * r.SM_SIZE + r.SM_PDI_CONTROL_OFFSET
            on = mbx_on if k < 2 else pd_on
            if on:
                self.mem[pdi] &= ~r.SM_PDI_DEACTIVATE & 0xFF
            else:
                self.mem[pdi] |= r.SM_PDI_DEACTIVATE
        if not mbx_on:
            self.outbox.clear()
            for k in (0, 1):
                self.mem[r.SM_BASE + k * r.SM_SIZE + r.SM_STATUS_OFFSET] = 0

    # ------------------------------------------------------------ physical access

    def read(self, addr: int, buf: bytearray | memoryview, off: int, length: int) -> bool:
        """Copy ``length`` bytes at ``addr`` into ``buf[off:]``; False when not performed."""
        end = addr + length
        if end > r.ADDRESS_SPACE:
            return False
        if addr < r.PROCESS_RAM:
            if addr < r.DC_SYSTEM_TIME + 8 and end > r.DC_SYSTEM_TIME:
                struct.pack_into("<Q", self.mem, r.DC_SYSTEM_TIME, self.system_time())
            buf[off : off + length] = self.mem[addr:end]
            return True
        post: list[int] = []
        for k, start, sm_end, control in self._sms:
            if addr < sm_end and end > start:
                if not self._sm_open(k):
                    return False
                if control & r.SM_DIR_MASK == r.SM_DIR_WRITE:
                    return False
                if control & r.SM_MODE_MASK == r.SM_MODE_MAILBOX:
                    if not self._mbx_full(k):
                        return False
                    if end >= sm_end:
                        post.append(k)
        buf[off : off + length] = self.mem[addr:end]
        for k in post:
            self._mbx_set_full(k, False)
            self._fill_read_mailbox()
        return True

    def write(self, addr: int, data: bytes | memoryview) -> bool:
        """Write ``data`` at ``addr`` with the ESC's side effects; False when not performed."""
        length = len(data)
        end = addr + length
        if end > r.ADDRESS_SPACE:
            return False
        if addr < r.PROCESS_RAM:
            self._write_registers(addr, data)
            return True
        completed: list[tuple[int, int]] = []
        for k, start, sm_end, control in self._sms:
            if addr < sm_end and end > start:
                if not self._sm_open(k):
                    return False
                if control & r.SM_DIR_MASK != r.SM_DIR_WRITE:
                    return False
                mailbox = control & r.SM_MODE_MASK == r.SM_MODE_MAILBOX
                if mailbox and self._mbx_full(k):
                    return False
                if end >= sm_end:
                    completed.append((k, control))
        self.mem[addr:end] = data
        for k, control in completed:
            if control & r.SM_MODE_MASK == r.SM_MODE_MAILBOX:
                self._mailbox_written(k)
            else:
                self.outputs_fresh = True
                self.last_output_ns = self.clock()
        return True

    def _write_registers(self, addr: int, data: bytes | memoryview) -> None:
        end = min(addr + len(data), r.PROCESS_RAM)
        mem, mask = self.mem, _WRITABLE
        old_activate = [mem[r.SM_BASE + k * r.SM_SIZE + r.SM_ACTIVATE_OFFSET] for k in (1,)]
        for i in range(addr, end):
            if mask[i]:
                mem[i] = data[i - addr]

        def touched(start: int, length: int) -> bool:
            return addr < start + length and end > start

        if touched(r.RX_ERROR_COUNTERS, 0x14):
            mem[r.RX_ERROR_COUNTERS : r.RX_ERROR_COUNTERS + 0x14] = bytes(0x14)
        if touched(r.EEPROM_CONTROL, 2):
            self._eeprom_command()
        if touched(r.FMMU_BASE, r.FMMU_SIZE * r.FMMU_COUNT):
            self._parse_fmmus()
        if touched(r.SM_BASE, r.SM_SIZE * r.SM_COUNT):
            self._parse_sms()
            act = r.SM_BASE + r.SM_SIZE + r.SM_ACTIVATE_OFFSET
            if touched(act, 1) and (mem[act] ^ old_activate[0]) & r.SM_ACTIVATE_REPEAT:
                self._repeat_mailbox()
        if touched(r.DC_RECEIVE_TIME_PORT0, 4):
            self._latch_receive_times()
        if touched(r.DC_CYCLIC_UNIT_CONTROL, 1):  # bits 1-3 and 6-7 are reserved: read 0
            mem[r.DC_CYCLIC_UNIT_CONTROL] &= r.DC_CYCLIC_UNIT_CONTROL_BITS
        if touched(r.DC_ACTIVATION, 1):
            self.sync0_active = mem[r.DC_ACTIVATION] & 0x03 == 0x03
        if touched(r.AL_CONTROL, 1):
            self._al_control(mem[r.AL_CONTROL])

    # ------------------------------------------------------------------ logical

    def logical(self, cmd: int, laddr: int, buf: bytearray, off: int, length: int) -> int:
        """LRD (10), LWR (11) or LRW (12) over ``buf[off:off+length]`` mapped at ``laddr``.

        Returns the working-counter increment: +1 for a read FMMU hit, +1 (LWR) or +2 (LRW)
        for a write FMMU hit.
        """
        read_hit = write_hit = False
        lend = laddr + length
        for log_start, log_end, phys, ftype in self._fmmus:
            if log_start >= lend or log_end <= laddr:
                continue
            lo = max(log_start, laddr)
            hi = min(log_end, lend)
            p = phys + (lo - log_start)
            o = off + (lo - laddr)
            n = hi - lo
            if ftype & r.FMMU_WRITE and cmd != 10:
                if self.write(p, memoryview(buf)[o : o + n]):
                    write_hit = True
            if ftype & r.FMMU_READ and cmd != 11:
                if self.read(p, buf, o, n):
                    read_hit = True
        return int(read_hit) + (2 if cmd == 12 else 1) * int(write_hit)

    def _parse_fmmus(self) -> None:
        out = []
        for k in range(r.FMMU_COUNT):
            base = r.FMMU_BASE + k * r.FMMU_SIZE
            log_start, log_len, _sb, _eb, phys, _pb, ftype, active = struct.unpack_from(
                "<IHBBHBBB", self.mem, base
            )
            if active & 1 and log_len and ftype & 0x03:
                out.append((log_start, log_start + log_len, phys, ftype & 0x03))
        self._fmmus = out

    # ------------------------------------------------------------- SyncManagers

    def _parse_sms(self) -> None:
        out = []
        for k in range(r.SM_COUNT):
            start, length, control, _st, activate, _pdi = struct.unpack_from(
                "<HHBBBB", self.mem, r.SM_BASE + k * r.SM_SIZE
            )
            if activate & r.SM_ACTIVATE_ENABLE and length:
                out.append((k, start, start + length, control))
        self._sms = out

    def sm(self, k: int) -> tuple[int, int, int, int]:
        """SyncManager ``k`` registers: (start, length, control, activate)."""
        start, length, control, _st, activate, _pdi = struct.unpack_from(
            "<HHBBBB", self.mem, r.SM_BASE + k * r.SM_SIZE
        )
        return start, length, control, activate

    def _sm_open(self, k: int) -> bool:
        pdi = self.mem[r.SM_BASE + k * r.SM_SIZE + r.SM_PDI_CONTROL_OFFSET]
        return not pdi & r.SM_PDI_DEACTIVATE

    def _mbx_full(self, k: int) -> bool:
        return bool(self.mem[r.SM_BASE + k * r.SM_SIZE + r.SM_STATUS_OFFSET] & 0x08)

    def _mbx_set_full(self, k: int, full: bool) -> None:
        at = r.SM_BASE + k * r.SM_SIZE + r.SM_STATUS_OFFSET
        if full:
            self.mem[at] |= r.SM_STATUS_MAILBOX_FULL
        else:
            self.mem[at] &= ~r.SM_STATUS_MAILBOX_FULL & 0xFF

    # ----------------------------------------------------------------- mailbox

    def _mailbox_written(self, k: int) -> None:
        start, length, _c, _a = self.sm(k)
        frame = bytes(self.mem[start : start + length])
        self._mbx_set_full(k, True)
        if self._held:  # the master gave up on them and asks again: they come now
            self.outbox.extend(self._held)
            self._held.clear()
        if self.coe is None:
            reply = None
        else:
            reply = self.coe.handle(frame)
        self._mbx_set_full(k, False)  # the application has read it
        key = _sdo_request_object(frame)
        if reply is not None and key is not None and self.late.get(key, 0) > 0:
            self.late[key] -= 1
            self._held.append(reply)
            reply = None
        if reply is not None:
            self.outbox.append(reply)
        self._fill_read_mailbox()

    def queue_mailbox(self, frame: bytes) -> None:
        """Queue a slave-initiated mailbox frame (e.g. an emergency) for the master."""
        if self.al_state & 0x0F != r.STATE_INIT:
            self.outbox.append(frame)
            self._fill_read_mailbox()

    def _read_mailbox_sm(self) -> int | None:
        for k, _s, _e, control in self._sms:
            if (
                control & r.SM_MODE_MASK == r.SM_MODE_MAILBOX
                and control & r.SM_DIR_MASK == r.SM_DIR_READ
            ):
                return k
        return None

    def _fill_read_mailbox(self) -> None:
        k = self._read_mailbox_sm()
        if k is None or not self.outbox or self._mbx_full(k) or not self._sm_open(k):
            return
        start, length, _c, _a = self.sm(k)
        frame = self.outbox.popleft()[:length]
        self.mem[start : start + length] = frame + bytes(length - len(frame))
        self.last_reply = frame
        self._mbx_set_full(k, True)

    def _repeat_mailbox(self) -> None:
        k = self._read_mailbox_sm()
        base = r.SM_BASE + r.SM_SIZE  # SM1 registers
        if k is not None and self.last_reply:
            start, length, _c, _a = self.sm(k)
            self.mem[start : start + length] = self.last_reply + bytes(
                length - len(self.last_reply)
            )
            self._mbx_set_full(k, True)
        repeat = self.mem[base + r.SM_ACTIVATE_OFFSET] & r.SM_ACTIVATE_REPEAT
        pdi = base + r.SM_PDI_CONTROL_OFFSET
        self.mem[pdi] = (self.mem[pdi] & ~r.SM_PDI_REPEAT_ACK & 0xFF) | repeat

    # ------------------------------------------------------------------ SII

    def _eeprom_command(self) -> None:
        mem = self.mem
        ctl = mem[r.EEPROM_CONTROL] | (mem[r.EEPROM_CONTROL + 1] << 8)
        cmd = ctl & r.EEPROM_CMD_MASK
        word = struct.unpack_from("<I", mem, r.EEPROM_ADDRESS)[0]
        status = r.EEPROM_READ_8_BYTES | (ctl & r.EEPROM_WRITE_ENABLE)
        if cmd == r.EEPROM_CMD_READ:
            chunk = bytes(self.sii[2 * word : 2 * word + 8])
            mem[r.EEPROM_DATA : r.EEPROM_DATA + 8] = chunk + b"\xff" * (8 - len(chunk))
        elif cmd == r.EEPROM_CMD_WRITE:
            if ctl & r.EEPROM_WRITE_ENABLE and 2 * word + 2 <= len(self.sii):
                self.sii[2 * word : 2 * word + 2] = mem[r.EEPROM_DATA : r.EEPROM_DATA + 2]
            else:
                status |= r.EEPROM_ERROR_ACK
        elif cmd == r.EEPROM_CMD_RELOAD:
            struct.pack_into("<H", mem, r.STATION_ALIAS, self.sii[8] | (self.sii[9] << 8))
        elif cmd != 0:
            status |= r.EEPROM_ERROR_ACK
        struct.pack_into("<H", mem, r.EEPROM_CONTROL, status)

    # ------------------------------------------------------------------ DC

    def system_time(self) -> int:
        """DC system time [ns]: local clock plus the offset the master wrote (0x0920)."""
        offset = struct.unpack_from("<q", self.mem, r.DC_SYSTEM_TIME_OFFSET)[0]
        return (self.dc_clock() + offset) & 0xFFFFFFFFFFFFFFFF

    def _latch_receive_times(self) -> None:
        now = self.dc_clock()
        self._latched_ns = now
        # port 0 sees the frame first; port 1 when it comes back from the slaves behind
        behind = 0 if self.mem[r.DL_STATUS] & 0x20 == 0 else 1
        struct.pack_into("<I", self.mem, r.DC_RECEIVE_TIME_PORT0, now & 0xFFFFFFFF)
        struct.pack_into("<I", self.mem, 0x0904, (now + 400 * behind) & 0xFFFFFFFF)
        struct.pack_into("<Q", self.mem, r.DC_RECEIVE_TIME_PU, now)

    # ------------------------------------------------------------------ AL

    def _al_control(self, control: int) -> None:
        requested = control & 0x0F
        ack = bool(control & r.AL_ACK_FLAG)
        status = self.mem[r.AL_STATUS]
        current = status & 0x0F
        if status & r.AL_ERROR_FLAG:
            if not ack:
                # a master must acknowledge an error; a request to go down still works
                if requested >= current or requested not in _VALID_STATES:
                    return
            else:
                self._set_al(current, AL_NO_ERROR, error=False)
        if requested not in _VALID_STATES:
            self._set_al(current, AL_UNKNOWN_STATE, error=True)
            return
        if requested == current:
            return
        if requested in self.refuse:
            self._set_al(current, self.refuse[requested], error=True)
            return
        if current == r.STATE_BOOT or requested == r.STATE_BOOT:
            # BOOT is entered from INIT and left to INIT only
            going_down = current == r.STATE_BOOT and requested == r.STATE_INIT
        else:
            going_down = requested < current
        if going_down:
            self._set_al(requested, AL_NO_ERROR, error=False)
            return
        if (current, requested) not in _ALLOWED:
            self._set_al(current, AL_INVALID_STATE_CHANGE, error=True)
            return
        code = self._check_transition(requested)
        if code:
            self._set_al(current, code, error=True)
        else:
            self._set_al(requested, AL_NO_ERROR, error=False)

    def _check_transition(self, requested: int) -> int:
        if requested in (r.STATE_PREOP, r.STATE_BOOT):
            return self._check_mailbox_sms()
        if requested == r.STATE_SAFEOP:
            return self._prepare_process_data()
        if requested == r.STATE_OP:
            if self.desc.dc_required:
                cycle = struct.unpack_from("<I", self.mem, r.DC_SYNC0_CYCLE)[0]
                fixed = self.desc.sync0_cycle_ns
                if not self.sync0_active or (fixed is not None and cycle != fixed):
                    return AL_INVALID_DC_SYNC
            self.last_output_ns = self.clock()
        return AL_NO_ERROR

    def _check_mailbox_sms(self) -> int:
        d = self.desc
        for k, (start, size, direction) in enumerate(
            (
                (d.mbx_out_offset, d.mbx_out_size, r.SM_DIR_WRITE),
                (d.mbx_in_offset, d.mbx_in_size, r.SM_DIR_READ),
            )
        ):
            s, length, control, activate = self.sm(k)
            if (
                s != start
                or length != size
                or not activate & r.SM_ACTIVATE_ENABLE
                or control & r.SM_MODE_MASK != r.SM_MODE_MAILBOX
                or control & r.SM_DIR_MASK != direction
            ):
                return AL_INVALID_MBX_CONFIG
        return AL_NO_ERROR

    def _prepare_process_data(self) -> int:
        """PRE-OP -> SAFE-OP: check the PDO mapping, SM2/SM3 and DC; build copy plans."""
        if self.od is None:
            return AL_INVALID_OUTPUT_CONFIG
        outs = pdo_map.assigned_entries(self.od, pdo.RXPDO_ASSIGN_INDEX)
        ins = pdo_map.assigned_entries(self.od, pdo.TXPDO_ASSIGN_INDEX)
        if pdo_map.check_mapping(outs, "controlword", pdo.RXPDO_DTYPE):
            return AL_INVALID_OUTPUT_CONFIG
        if pdo_map.check_mapping(ins, "statusword", pdo.TXPDO_DTYPE):
            return AL_INVALID_INPUT_CONFIG
        try:
            out_plan, out_size = pdo_map.copy_plan(outs, pdo.RXPDO_DTYPE, self.records)
            in_plan, in_size = pdo_map.copy_plan(ins, pdo.TXPDO_DTYPE, self.records)
        except ValueError:
            return AL_INVALID_OUTPUT_CONFIG
        for k, offset, size, direction, code in (
            (2, self.desc.outputs_offset, out_size, r.SM_DIR_WRITE, AL_INVALID_OUTPUT_CONFIG),
            (3, self.desc.inputs_offset, in_size, r.SM_DIR_READ, AL_INVALID_INPUT_CONFIG),
        ):
            start, length, control, activate = self.sm(k)
            if (
                start != offset
                or length != size
                or not activate & r.SM_ACTIVATE_ENABLE
                or control & r.SM_MODE_MASK != r.SM_MODE_BUFFERED
                or control & r.SM_DIR_MASK != direction
            ):
                return code
        if self.sync0_active:
            cycle = struct.unpack_from("<I", self.mem, r.DC_SYNC0_CYCLE)[0]
            if cycle < 125_000:
                return AL_INVALID_SYNC_CYCLE
        # the drive's application checks the sync/latch unit assignment its ESI states
        # (AssignActivate's low byte in 0x0980) before SAFE-OP, as SSC-based drives do
        want = self.desc.assign_activate & 0xFF
        if self.desc.dc_required and self.mem[r.DC_CYCLIC_UNIT_CONTROL] != want:
            return AL_INVALID_DC_SYNC
        self.output_plan = out_plan
        self.input_plan = in_plan
        return AL_NO_ERROR

    def raise_al_error(self, code: int) -> None:
        """The application reports an error: drop to SAFE-OP (or stay lower) with ``code``."""
        self._set_al(min(self.al_state & 0x0F, r.STATE_SAFEOP), code, error=True)

    def check_watchdog(self, now_ns: int) -> None:
        """SM watchdog: in OP without an SM2 write for the watchdog time -> SAFE-OP + 0x001B."""
        if self.al_state != r.STATE_OP:
            return
        _s, _l, control, _a = self.sm(2)
        if not control & r.SM_WATCHDOG_ENABLE:
            return
        div = struct.unpack_from("<H", self.mem, r.WATCHDOG_DIVIDER)[0]
        ticks = struct.unpack_from("<H", self.mem, r.WATCHDOG_TIME_PD)[0]
        limit_ns = ticks * (div + 2) * 40
        if limit_ns and now_ns - self.last_output_ns > limit_ns:
            self._set_al(r.STATE_SAFEOP, AL_SM_WATCHDOG, error=True)

    # ---------------------------------------------------------- process data (PDI)

    def pull_outputs(self, rec: np.ndarray) -> bool:
        """Copy the SM2 buffer into ``rec`` (uint8 view of one RxPDO record; with
        ``records``: of the whole record array) when in OP.

        Returns True when the slave is in OP (the outputs are valid).
        """
        if self.al_state != r.STATE_OP:
            return False
        base = self.desc.outputs_offset
        src = self.mem_np
        for sm_off, rec_off, size in self.output_plan:
            rec[rec_off : rec_off + size] = src[base + sm_off : base + sm_off + size]
        return True

    def push_inputs(self, rec: np.ndarray) -> None:
        """Copy ``rec`` (uint8 view of one TxPDO record; with ``records``: of the whole
        record array) into the SM3 buffer."""
        base = self.desc.inputs_offset
        dst = self.mem_np
        for sm_off, rec_off, size in self.input_plan:
            dst[base + sm_off : base + sm_off + size] = rec[rec_off : rec_off + size]
