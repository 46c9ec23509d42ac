"""Drive profiles modelled on the vendor files in ../shared/data/drives (hand-written, for
the driver tests: layouts, padding, fixed PDOs, start-up modes, DC), and a config writer
that gives each axis of configs/er3a.yaml one of them."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

from hofto_hw.config.drive_profile import DriveProfile
from hofto_hw.config.loader import dump_yaml

ROOT = Path(__file__).resolve().parents[2]


def _e(index: int, bits: int, sub: int = 0) -> dict[str, int]:
    return {"index": index, "subindex": sub, "bits": bits}


PAD8 = _e(0, 8)
CSP = {"supported": ["pp", "pv", "csp", "csv", "cst"], "loop": "csp", "set_by": "pdo"}


def _base(name: str, vendor: int, product: int, **kw: Any) -> dict[str, Any]:
    return {
        "profile": 1,
        "name": name,
        "bus": "ethercat",
        "identity": {"vendor_id": vendor, "product_code": product},
        "modes": CSP,
    } | kw


#: Elmo-like: one fixed Rx and Tx PDO each, controlword last, 8-bit objects padded to 16
#: bits, no torque offset mapped (feed-forward through CST only), error code by SDO,
#: interpolation period written at start-up
ELMO = _base(
    "test_elmo",
    0x0000009A,
    0x00030924,
    rx_pdos=[
        {
            "index": 0x1605,
            "fixed": True,
            "entries": [
                _e(0x607A, 32),
                _e(0x60FF, 32),
                _e(0x6071, 16),
                _e(0x6060, 8),
                PAD8,
                _e(0x6040, 16),
            ],
        }
    ],
    tx_pdos=[
        {
            "index": 0x1A07,
            "fixed": True,
            "entries": [
                _e(0x6064, 32),
                _e(0x60FD, 32),
                _e(0x606C, 32),
                _e(0x6077, 16),
                _e(0x6078, 16),
                _e(0x6041, 16),
                _e(0x6061, 8),
                PAD8,
            ],
        }
    ],
    fallbacks={"torque_offset": "target_torque_in_cst", "error_code": "sdo"},
    objects={"sdo": ["torque_offset", "error_code"]},
    startup=[
        {
            "index": 0x60C2,
            "subindex": 1,
            "value": "loop_period",
            "bits": 8,
            "transition": "PS",
            "comment": "interpolation period",
        },
        {"index": 0x60C2, "subindex": 2, "value": -3, "bits": 8, "transition": "PS"},
    ],
    dc={"assign_activate": 0x300},
)
#: Inovance-like: configurable 0x1600/0x1A00, mode set by a start-up SDO (not mapped), no
#: mode display mapped, DC only
INOVANCE = _base(
    "test_inovance",
    0x00100000,
    0x000C010D,
    modes={
        "supported": ["pp", "pv", "tq", "hm", "csp", "csv", "cst"],
        "loop": "csp",
        "set_by": "startup",
    },
    rx_pdos=[
        {
            "index": 0x1600,
            "fixed": False,
            "entries": [
                _e(0x6040, 16),
                _e(0x607A, 32),
                _e(0x60FF, 32),
                _e(0x6071, 16),
                _e(0x60B2, 16),
            ],
        }
    ],
    tx_pdos=[
        {
            "index": 0x1A00,
            "fixed": False,
            "entries": [
                _e(0x603F, 16),
                _e(0x6041, 16),
                _e(0x6064, 32),
                _e(0x606C, 32),
                _e(0x6077, 16),
                _e(0x6078, 16),
                _e(0x60FD, 32),
            ],
        }
    ],
    fallbacks={"mode": "startup", "mode_display": "sdo"},
    objects={"sdo": ["mode", "mode_display"]},
    startup=[{"index": 0x6060, "value": 8, "bits": 8, "transition": "PS", "comment": "CSP"}],
    dc={"assign_activate": 0x300},
)
#: Nanotec-like: two Rx and two Tx PDOs, DC 0x330 with SYNC0 fixed at 1 ms, 250 us shift
NANOTEC = _base(
    "test_nanotec",
    0x0000026C,
    0x00000007,
    rx_pdos=[
        {"index": 0x1600, "fixed": False, "entries": [_e(0x6040, 16), _e(0x6060, 8)]},
        {
            "index": 0x1601,
            "fixed": False,
            "entries": [_e(0x607A, 32), _e(0x60FF, 32), _e(0x6071, 16), _e(0x60B2, 16)],
        },
    ],
    tx_pdos=[
        {"index": 0x1A00, "fixed": False, "entries": [_e(0x6041, 16), _e(0x6061, 8)]},
        {
            "index": 0x1A01,
            "fixed": False,
            "entries": [
                _e(0x6064, 32),
                _e(0x606C, 32),
                _e(0x6077, 16),
                _e(0x6078, 16),
                _e(0x603F, 16),
                _e(0x60FD, 32),
            ],
        },
    ],
    dc={"assign_activate": 0x330, "sync0_cycle_ns": 1_000_000, "sync0_shift_ns": 250_000},
)
#: a sparse drive (Faulhaber-like objects on EtherCAT): no 0x6077/0x6071/0x60B2/0x603F/
#: 0x60FD, a vendor object mapped, free run (no DC)
SPARSE = _base(
    "test_sparse",
    0x00000147,
    0x00003150,
    modes={"supported": ["pp", "pv", "csp", "csv"], "loop": "csp", "set_by": "pdo"},
    rx_pdos=[
        {
            "index": 0x1600,
            "fixed": False,
            "entries": [
                _e(0x6040, 16),
                _e(0x6060, 8),
                PAD8,
                _e(0x607A, 32),
                _e(0x60FF, 32),
                _e(0x60B8, 16),
            ],
        }
    ],
    tx_pdos=[
        {
            "index": 0x1A00,
            "fixed": False,
            "entries": [
                _e(0x6041, 16),
                _e(0x6061, 8),
                PAD8,
                _e(0x6064, 32),
                _e(0x606C, 32),
                _e(0x6078, 16),
                _e(0x60B9, 16),
            ],
        }
    ],
    fallbacks={
        "target_torque": "unavailable",
        "torque_offset": "unavailable",
        "torque": "current",
        "error_code": "sdo",
        "digital_inputs": "none",
    },
    objects={
        "absent": ["target_torque", "torque_offset", "torque", "error_code", "digital_inputs"]
    },
)
#: SOMANET-like: three Rx and four Tx PDOs, fixed assignment alternatives, DC 0x300
SOMANET = _base(
    "test_somanet",
    0x000022D2,
    0x00000201,
    rx_pdos=[
        {"index": 0x1600, "fixed": True, "entries": [_e(0x6040, 16), _e(0x6060, 8)]},
        {"index": 0x1601, "fixed": True, "entries": [_e(0x607A, 32), _e(0x60FF, 32)]},
        {"index": 0x1602, "fixed": True, "entries": [_e(0x6071, 16), _e(0x60B2, 16)]},
    ],
    tx_pdos=[
        {"index": 0x1A00, "fixed": True, "entries": [_e(0x6041, 16), _e(0x6061, 8)]},
        {"index": 0x1A01, "fixed": True, "entries": [_e(0x6064, 32), _e(0x606C, 32)]},
        {"index": 0x1A02, "fixed": True, "entries": [_e(0x6077, 16), _e(0x6078, 16)]},
        {"index": 0x1A03, "fixed": True, "entries": [_e(0x603F, 16), _e(0x60FD, 32)]},
    ],
    dc={"assign_activate": 0x300},
)
#: the built-in layout spelled as a profile (vendor/product of configs/er3a.yaml)
BUILTINLIKE = _base(
    "test_builtin",
    0x00000A5F,
    0x00402001,
    modes={"supported": ["csp", "csv", "cst"], "loop": "csp", "set_by": "pdo"},
    rx_pdos=[
        {
            "index": 0x1600,
            "fixed": False,
            "entries": [
                _e(0x6040, 16),
                _e(0x6060, 8),
                _e(0x607A, 32),
                _e(0x60FF, 32),
                _e(0x6071, 16),
                _e(0x60B2, 16),
            ],
        }
    ],
    tx_pdos=[
        {
            "index": 0x1A00,
            "fixed": False,
            "entries": [
                _e(0x6041, 16),
                _e(0x6061, 8),
                _e(0x6064, 32),
                _e(0x606C, 32),
                _e(0x6077, 16),
                _e(0x6078, 16),
                _e(0x603F, 16),
                _e(0x60FD, 32),
            ],
        }
    ],
)

MIXED = [ELMO, INOVANCE, NANOTEC, SPARSE, SOMANET, BUILTINLIKE]


def _axis_block(entries: list[dict[str, int]], k: int) -> list[dict[str, int]]:
    """``entries`` moved to CiA-402 axis k (objects at 0x6000 + 0x800·k; padding kept)."""
    return [e | {"index": e["index"] + 0x800 * k} if e["index"] else dict(e) for e in entries]


#: SYNTHETIC two-axis drive: none of the vendor files in ../shared/data/drives describes a
#: multi-axis device, so this is BUILTINLIKE with a second axis block (CiA 402-1: axis 1's
#: objects at 0x6800.., its own PDOs 0x1610 / 0x1A10), DC 0x300. Not a real product.
TWO_AXIS = _base(
    "test_two_axis_synthetic",
    0x00000A5F,
    0x00402002,
    description="SYNTHETIC two-axis CiA-402 drive for the multi-axis tests (no vendor file)",
    axes=2,
    modes={"supported": ["csp", "csv", "cst"], "loop": "csp", "set_by": "pdo"},
    rx_pdos=[
        {"index": 0x1600 + 0x10 * k, "fixed": False,
         "entries": _axis_block(BUILTINLIKE["rx_pdos"][0]["entries"], k)}
        for k in range(2)
    ],
    tx_pdos=[
        {"index": 0x1A00 + 0x10 * k, "fixed": False,
         "entries": _axis_block(BUILTINLIKE["tx_pdos"][0]["entries"], k)}
        for k in range(2)
    ],
    dc={"assign_activate": 0x300},
)  # fmt: skip


def write_two_axis_config(folder: Path, interface: str = "ecm0", **bus: Any) -> Path:
    """configs/er3a.yaml on three TWO_AXIS drives (joints 2k, 2k+1 on device k, axes 0, 1),
    ``transport: ethercat`` on ``interface``; returns its path."""
    path = write_mixed_config(folder, [TWO_AXIS] * 6, transport="ethercat", interface=interface,
                              **bus)  # fmt: skip
    data = yaml.safe_load(path.read_text())
    for i, d in enumerate(data["bus"]["drives"]):
        d["device"], d["device_axis"] = divmod(i, 2)
    path.write_text(dump_yaml(data, sort_keys=False))
    return path


def profile(data: dict[str, Any]) -> DriveProfile:
    return DriveProfile.model_validate(data)


def write_mixed_config(
    folder: Path,
    profiles: list[dict[str, Any]] | None = None,
    base: Path | None = None,
    **bus: Any,
) -> Path:
    """configs/er3a.yaml with ``bus.drives[i].profile`` = a file of ``profiles[i]`` in
    ``folder`` (identity set to the profile's) and ``bus`` keys merged; returns its path."""
    profiles = MIXED if profiles is None else profiles
    data = yaml.safe_load((base or ROOT / "configs" / "er3a.yaml").read_text())
    for i, (d, p) in enumerate(zip(data["bus"]["drives"], profiles, strict=True)):
        path = folder / f"{p['name']}.yaml"
        path.write_text(dump_yaml(p, sort_keys=False))
        d["profile"] = str(path)
        d["identity"] = {
            "vendor_id": p["identity"]["vendor_id"],
            "product_code": p["identity"]["product_code"],
        }
        del i
    data["bus"].update(bus)
    for key in ("urdf", "parameters"):
        for section in (data.get("robot", {}),):
            if isinstance(section.get(key), str) and not Path(section[key]).is_absolute():
                section[key] = str((ROOT / "configs" / section[key]).resolve())
    out = folder / "mixed.yaml"
    out.write_text(dump_yaml(data, sort_keys=False))
    return out


def _can(name: str, vendor: int, product: int, rx, tx, rcomm, tcomm, **kw: Any) -> dict:
    return {
        "profile": 1,
        "name": name,
        "bus": "canopen",
        "identity": {"vendor_id": vendor, "product_code": product},
        "modes": kw.pop("modes", CSP),
        "rx_pdos": rx,
        "tx_pdos": tx,
        "canopen": {
            "bitrates": [1_000_000],
            "max_entries": kw.pop("max_entries", 8),
            "rpdo": rcomm,
            "tpdo": tcomm,
        },
    } | kw


def _comm(base: int, ttype: int = 1, enabled: bool = False) -> dict[str, Any]:
    return {"cob_id_base": base, "transmission_type": ttype, "enabled_by_default": enabled}


#: ZeroErr-like: PDOs disabled by default, two RPDOs / two TPDOs, 1 Mbit/s only
CAN_ZEROERR = _can(
    "test_can_zeroerr",
    0x5A65726F,
    0x00029252,
    [
        {"index": 0x1600, "fixed": False, "entries": [_e(0x6040, 16), _e(0x607A, 32)]},
        {
            "index": 0x1601,
            "fixed": False,
            "entries": [_e(0x60FF, 32), _e(0x6071, 16), _e(0x6060, 8)],
        },
    ],
    [
        {
            "index": 0x1A00,
            "fixed": False,
            "entries": [_e(0x6041, 16), _e(0x6064, 32), _e(0x6077, 16)],
        },
        {
            "index": 0x1A01,
            "fixed": False,
            "entries": [_e(0x606C, 32), _e(0x6061, 8), _e(0x603F, 16)],
        },
    ],
    [_comm(0x200), _comm(0x300)],
    [_comm(0x180), _comm(0x280)],
    fallbacks={
        "torque_offset": "target_torque_in_cst",
        "current": "unavailable",
        "digital_inputs": "none",
    },
)
#: Faulhaber-like: at most four entries per PDO, no torque objects, no error code object
#: (EMCY), mode by start-up SDO
CAN_FAULHABER = _can(
    "test_can_faulhaber",
    0x00000147,
    0x00003150,
    [
        {"index": 0x1600, "fixed": False, "entries": [_e(0x6040, 16), _e(0x607A, 32)]},
        {"index": 0x1601, "fixed": False, "entries": [_e(0x60FF, 32)]},
    ],
    [
        {"index": 0x1A00, "fixed": False, "entries": [_e(0x6041, 16), _e(0x6064, 32)]},
        {
            "index": 0x1A01,
            "fixed": False,
            "entries": [_e(0x606C, 32), _e(0x6078, 16), _e(0x6061, 8)],
        },
    ],
    [_comm(0x200, 1, True), _comm(0x300)],
    [_comm(0x180, 1, True), _comm(0x280)],
    modes={"supported": ["pp", "pv", "csp", "csv"], "loop": "csp", "set_by": "startup"},
    max_entries=4,
    startup=[{"index": 0x6060, "value": 8, "bits": 8, "transition": "PO"}],
    fallbacks={
        "mode": "startup",
        "target_torque": "unavailable",
        "torque_offset": "unavailable",
        "torque": "current",
        "error_code": "emcy",
        "digital_inputs": "none",
    },
    objects={
        "absent": ["target_torque", "torque_offset", "torque", "error_code", "digital_inputs"]
    },
)
#: Technosoft-like: fixed TPDO1, every-SYNC TPDOs, no 0x60B2/0x603F
CAN_TECHNOSOFT = _can(
    "test_can_technosoft",
    0x000001A3,
    0x00000290,
    [
        {
            "index": 0x1600,
            "fixed": False,
            "entries": [_e(0x6040, 16), _e(0x6060, 8), PAD8, _e(0x607A, 32)],
        },
        {"index": 0x1601, "fixed": False, "entries": [_e(0x60FF, 32), _e(0x6071, 16)]},
    ],
    [
        {"index": 0x1A00, "fixed": True, "entries": [_e(0x6041, 16), _e(0x6061, 8)]},
        {"index": 0x1A01, "fixed": False, "entries": [_e(0x6064, 32), _e(0x606C, 32)]},
        {"index": 0x1A02, "fixed": False, "entries": [_e(0x6077, 16), _e(0x6078, 16)]},
    ],
    [_comm(0x200, 1, True), _comm(0x300, 1, True)],
    [_comm(0x180, 1, True), _comm(0x280, 1, True), _comm(0x380, 1, True)],
    fallbacks={
        "torque_offset": "target_torque_in_cst",
        "error_code": "emcy",
        "digital_inputs": "none",
    },
    objects={"absent": ["torque_offset", "error_code"]},
)
CAN_MIXED = [CAN_ZEROERR, CAN_FAULHABER, CAN_TECHNOSOFT] * 2


def _can_two_axis(emcy_axis_byte: int | None) -> dict[str, Any]:
    from drivers.canopen import layout

    rx = [p.entries for p in layout.RPDOS]
    tx = [p.entries for p in layout.TPDOS]

    def pdos(base: int, blocks: list) -> list[dict[str, Any]]:
        return [
            {
                "index": base + len(blocks) * k + j,
                "fixed": False,
                "entries": _axis_block([_e(e.index, e.bit_length) for e in b], k),
            }
            for k in range(2)
            for j, b in enumerate(blocks)
        ]

    name = "test_can_two_axis_synthetic" + ("" if emcy_axis_byte is not None else "_no_emcy_axis")
    out = _can(
        name,
        0x00000A5F,
        0x00402003,
        pdos(0x1600, rx),
        pdos(0x1A00, tx),
        # PDO n of the node: CiA 301's default COB-IDs (drivers/canopen/layout.pdo_cob_base)
        [_comm(layout.pdo_cob_base("rpdo", n), 1, True) for n in range(1, 5)],
        [_comm(layout.pdo_cob_base("tpdo", n), 1, True) for n in range(1, 5)],
        description="SYNTHETIC two-axis CiA-402 CANopen drive for the multi-axis tests (no "
        "vendor file): the built-in CANopen layout per axis, RPDO1/2 + TPDO1/2 axis 0, "
        "RPDO3/4 + TPDO3/4 axis 1 (objects at 0x6800..)",
        axes=2,
        modes={"supported": ["csp", "csv", "cst"], "loop": "csp", "set_by": "pdo"},
        fallbacks={"error_code": "emcy", "digital_inputs": "none"},
    )
    out["canopen"]["emcy_axis_byte"] = emcy_axis_byte
    return out


#: SYNTHETIC two-axis CANopen drive (no vendor file describes one): one node, two CiA-402
#: axes, four RPDOs and four TPDOs, its EMCY names the axis in byte 3
CAN_TWO_AXIS = _can_two_axis(3)
#: the same drive whose EMCY does not say which axis (the master reads 0x603F by SDO)
CAN_TWO_AXIS_NO_EMCY_AXIS = _can_two_axis(None)


def write_can_two_axis_config(
    folder: Path, profile: dict[str, Any] | None = None, **bus: Any
) -> Path:
    """configs/er3a_canopen.yaml on three two-axis CANopen nodes (joints 2k, 2k+1 on node
    k + 1, axes 0, 1) of ``profile`` (default CAN_TWO_AXIS), ``bus`` keys merged; returns
    its path."""
    prof = CAN_TWO_AXIS if profile is None else profile
    path = write_mixed_config(
        folder, [prof] * 6, base=ROOT / "configs" / "er3a_canopen.yaml", **bus
    )
    data = yaml.safe_load(path.read_text())
    for i, d in enumerate(data["bus"]["drives"]):
        d["device"], d["device_axis"] = divmod(i, 2)
    path.write_text(dump_yaml(data, sort_keys=False))
    return path
