"""Worst-case CAN bus load of a cyclic CANopen configuration.

Classic CAN, 11-bit identifiers, worst-case bit stuffing: a frame with ``s`` data bytes
takes ``34 + 8s + 13 + floor((34 + 8s - 1) / 4)`` bit times (34 stuffable header/CRC
bits, 13 bits of delimiters, ACK, end of frame and interframe space that are not stuffed):
135 bits for 8 bytes, 55 for a SYNC.

CAN FD (ISO 11898-1:2015, 11-bit ids, bit-rate switch): the arbitration phase (SOF, id,
RRS, IDE, FDF, res, BRS; worst-case stuffed) and the tail (CRC delimiter, ACK, EOF, IFS)
run at the nominal bitrate; ESI, DLC, data, stuff count, CRC (17 bits up to 16 bytes, 21
above) with its fixed stuff bits run at the data bitrate, data and DLC worst-case stuffed.
Payloads round up to the next valid FD length (12, 16, 20, 24, 32, 48, 64).

Load = time on the wire per cycle × rate. :func:`check_bus_load` refuses a configuration
above the limit naming the load, the limit and the highest rate that fits.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from hofto_hw.errors import ConfigError

FD_LENGTHS = (0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64)


def classic_frame_bits(size: int) -> int:
    """Worst-case bit times of a classic CAN data frame with ``size`` (0..8) bytes, 11-bit id."""
    if not 0 <= size <= 8:
        raise ValueError(f"a classic CAN frame carries 0..8 bytes, not {size}")
    stuffable = 34 + 8 * size
    return stuffable + 13 + (stuffable - 1) // 4


def fd_length(size: int) -> int:
    """Smallest valid CAN FD payload length >= ``size``."""
    for n in FD_LENGTHS:
        if n >= size:
            return n
    raise ValueError(f"a CAN FD frame carries at most 64 bytes, not {size}")


def fd_frame_bits(size: int) -> tuple[int, int]:
    """Worst-case (nominal-rate bits, data-rate bits) of a CAN FD frame with BRS, 11-bit id."""
    n = fd_length(size)
    arbitration = 17  # SOF + 11 id + RRS + IDE + FDF + res + BRS
    nominal = arbitration + (arbitration - 1) // 4 + 1 + 1 + 1 + 7 + 3  # + CRC del, ACK, EOF, IFS
    crc = 17 if n <= 16 else 21
    stuffable = 1 + 4 + 8 * n  # ESI + DLC + data
    data = stuffable + (stuffable - 1) // 4 + 4 + crc + math.ceil((4 + crc) / 4)
    return nominal, data


@dataclass(frozen=True)
class BusLoad:
    """Result of :func:`bus_load`: bits per cycle, time per cycle [s], load at ``rate_hz``."""

    bits_per_cycle: int
    seconds_per_cycle: float
    rate_hz: float
    load: float  # fraction of the bus time, 0..
    limit: float

    def highest_rate(self, limit: float | None = None) -> float:
        """Highest cycle rate [Hz] at which the load stays at or below ``limit``."""
        return (self.limit if limit is None else limit) / self.seconds_per_cycle


def bus_load(
    payloads: Sequence[int],
    rate_hz: float,
    bitrate: float,
    data_bitrate: float | None = None,
    limit: float = 0.7,
) -> BusLoad:
    """Worst-case load of sending frames with ``payloads`` [byte] every cycle at ``rate_hz``.

    ``bitrate`` [bit/s] is the (nominal) bitrate; ``data_bitrate`` [bit/s] switches to CAN FD
    frames with that data-phase bitrate (None = classic CAN).
    """
    if rate_hz <= 0 or bitrate <= 0 or (data_bitrate is not None and data_bitrate <= 0):
        raise ValueError("rate and bitrates must be > 0")
    bits = 0
    seconds = 0.0
    for s in payloads:
        if data_bitrate is None:
            b = classic_frame_bits(s)
            bits += b
            seconds += b / bitrate
        else:
            nom, dat = fd_frame_bits(s)
            bits += nom + dat
            seconds += nom / bitrate + dat / data_bitrate
    return BusLoad(bits, seconds, float(rate_hz), seconds * rate_hz, float(limit))


def check_bus_load(load: BusLoad, where: str = "bus") -> None:
    """Raise ConfigError when ``load.load`` exceeds ``load.limit``, naming both and the
    highest feasible rate."""
    if load.load > load.limit:
        raise ConfigError(
            f"{where}: bus load {load.load * 100:.0f} % at {load.rate_hz:g} Hz "
            f"({load.bits_per_cycle} bits per cycle, worst case) exceeds the limit "
            f"{load.limit * 100:.0f} %; the highest feasible rate is "
            f"{math.floor(load.highest_rate()):d} Hz"
        )


def configured_load(bus: object, rate_hz: float) -> BusLoad:
    """Worst-case load of a :class:`hofto_hw.config.drives.BusConfig` (``transport:
    canopen``) at the loop rate ``rate_hz`` with this package's PDO layout."""
    from drivers.canopen.layout import frame_payloads
    from hofto_hw.config.drives import CANopenOptions

    opts = getattr(bus, "canopen", None) or CANopenOptions()
    n = len(bus.drives)  # type: ignore[attr-defined]
    return bus_load(frame_payloads(n), rate_hz, opts.bitrate, opts.data_bitrate, opts.load_limit)
