"""SimBus: an in-process :class:`~drivers.transport.Transport` over emulated CiA-402 drives.

The fast path for unit tests and the default demo. Each :meth:`SimBus.exchange` is one bus
cycle: the drives take ``rx``, step the plant by one tick and answer in ``tx``. Code above
the transport cannot tell it from EtherCAT; SDOs go to each drive's object dictionary.

Fault injection for tests: :meth:`SimBus.drop_cycles` loses the next frames (exchange
returns :data:`~drivers.transport.STATUS_NO_RESPONSE`, ``tx`` keeps its last values, the
drives see no RxPDO and fault with 0x8130 after their watchdog), and
:meth:`SimBus.inject_fault` forwards to :meth:`EmulatedDrives.inject_fault`.

Built from a whole config by :func:`hofto_hw.runtime.build.build_sim_bus`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from drivers.sim.drive import EmulatedDrives, LoopTuning
from drivers.sim.object_dictionary import SdoAbort
from drivers.sim.plant import Plant
from drivers.transport import (
    STATUS_NO_RESPONSE,
    STATUS_NOT_OPEN,
    STATUS_OK,
    SdoAbortError,
    Transport,
    TransportError,
)
from hofto_hw.config.drives import BusConfig, DriveConfig


class SimBus(Transport):
    """In-process bus: ``rx``/``tx`` exchanged with :class:`EmulatedDrives` every cycle.

    Simulated time advances by ``plant.dt`` per exchange (so ``cycle_time == plant.dt``)
    and :meth:`wait_next_cycle` does not sleep.
    """

    def __init__(
        self,
        plant: Plant,
        drives: Sequence[DriveConfig],
        *,
        axis_names: list[str] | None = None,
        tuning: LoopTuning | None = None,
        watchdog_cycles: int = 3,
        profiles: Sequence[Any] | None = None,
    ) -> None:
        super().__init__(len(drives), plant.dt, axis_names)
        self.drives = EmulatedDrives(
            plant,
            drives,
            tuning=tuning,
            watchdog_cycles=watchdog_cycles,
            names=self.axis_names,
            profiles=profiles,
        )
        #: the profile per drive (None: the built-in layout, the records go as they are)
        self.profiles = list(profiles) if profiles is not None else [None] * self.n_axes
        self.use_fallbacks(self.profiles)
        #: start-up SDOs written at the last open
        self.startup_written = 0
        self._wired = False
        self.plant = plant
        self.is_open = False
        self.cycles = 0
        self._drop = 0
        np.copyto(self.tx, self.drives.tx)

    @classmethod
    def from_config(
        cls, bus: BusConfig, plant: Plant, axis_names: list[str] | None = None
    ) -> SimBus:
        """A SimBus for ``bus.drives`` on ``plant``; it cycles at ``plant.dt``."""
        profiles = None
        if any(d.profile for d in bus.drives):
            from drivers.cia402.profiles import profiles_of_bus

            profiles = profiles_of_bus(bus)
        return cls(plant, bus.drives, axis_names=axis_names, profiles=profiles)

    # -------------------------------------------------------------- lifecycle

    def open(self) -> None:
        """Start cyclic exchange (the emulated drives lock their PDO mapping).

        Drives with a profile are configured as a master configures them (start-up SDOs,
        PDOs written, assigned and read back, :func:`drivers.cia402.profiles.configure_pdos`)
        and the process data then travels in each drive's own layout
        (:class:`drivers.cia402.wire.WireImage`): what a drive does not map does not reach
        it, and what it does not report keeps its defined value."""
        if any(p is not None for p in self.profiles):
            from drivers.cia402.profiles import configure_pdos, csp_adapter, write_startup
            from drivers.cia402.wire import BUILTIN_LAYOUT, WireImage

            self.startup_written = 0
            layouts = []
            for i, prof in enumerate(self.profiles):
                if prof is None:
                    layouts.append(BUILTIN_LAYOUT)
                    continue
                self.startup_written += write_startup(self, i, prof, ("IP", "PS", "SO", "PO"))
                layouts.append(configure_pdos(self, i, prof, TransportError))
            self.wire = WireImage(layouts, self.axis_names)
            self.wire.bind_master(self.rx, self.tx)
            self.wire.set_adapter(
                csp_adapter(self.profiles, self.cycle_time, self.drives.counts_per_rev)
            )
            self._wired = not self.wire.builtin
            if self._wired:
                # in one process the bytes need no wire order: what each drive maps is
                # copied in place (two masked copies a cycle); what it does not map keeps
                # its value on either side (the master's: its defined default)
                self._rx_mask, self._tx_mask = self.wire.mapped_bytes()
                self._rx_flat = self.rx.view(np.uint8).reshape(-1)
                self._tx_flat = self.tx.view(np.uint8).reshape(-1)
                self._drv_rx_flat = self.drives.rx.view(np.uint8).reshape(-1)
                self._drv_tx_flat = self.drives.tx.view(np.uint8).reshape(-1)
                self.wire.drive_tx(self.drives.tx)
                self.wire.decode_tx()
                if self.derived is not None:
                    self.derived.reset()
                    self.derived.apply(self.sample_dt)
        self.is_open = True
        for od in self.drives.ods:
            od.pdo_locked = True

    def close(self) -> None:
        """Stop cyclic exchange; the drives will miss frames if stepped further."""
        self.is_open = False
        for od in self.drives.ods:
            od.pdo_locked = False

    def exchange(self) -> int:
        """One cycle: rx -> drives -> plant tick -> tx. Returns a status code; never raises."""
        if not self.is_open:
            return STATUS_NOT_OPEN
        self.cycles += 1
        if self._drop > 0:
            self._drop -= 1
            self.drives.step(None)
            return STATUS_NO_RESPONSE
        if self._wired:
            np.copyto(self._drv_rx_flat, self.wire.adapt_rx(), where=self._rx_mask)
            self.drives.step(self.drives.rx)
            np.copyto(self._tx_flat, self._drv_tx_flat, where=self._tx_mask)
            self.wire.decode_units()
            if self.derived is not None:
                self.derived.apply(self.sample_dt)
            return STATUS_OK
        self.drives.step(self.rx)
        np.copyto(self.tx, self.drives.tx)
        return STATUS_OK

    def wait_next_cycle(self) -> None:
        """Simulated time: nothing to wait for."""

    # ------------------------------------------------------------ fault injection

    def drop_cycles(self, count: int = 1) -> None:
        """Lose the next ``count`` frames in both directions."""
        self._drop += int(count)

    def inject_fault(self, axis: int, kind: str, persistent: bool = False) -> None:
        """Make drive ``axis`` raise fault ``kind`` (see drivers.sim.drive.FAULTS)."""
        self.drives.inject_fault(axis, kind, persistent)

    # -------------------------------------------------------------------- SDO

    def sdo_read(self, axis: int, index: int, subindex: int) -> bytes:
        """Read from drive ``axis``'s object dictionary; raises SdoAbortError."""
        self._check_axis(axis)
        try:
            return self.drives.ods[axis].read(index, subindex)
        except SdoAbort as a:
            raise SdoAbortError(
                axis, index, subindex, a.code, "read", self.axis_names[axis]
            ) from None

    def sdo_write(self, axis: int, index: int, subindex: int, data: bytes) -> None:
        """Write to drive ``axis``'s object dictionary; raises SdoAbortError."""
        self._check_axis(axis)
        try:
            self.drives.ods[axis].write(index, subindex, bytes(data))
        except SdoAbort as a:
            raise SdoAbortError(
                axis, index, subindex, a.code, "write", self.axis_names[axis]
            ) from None
