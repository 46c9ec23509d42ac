"""A small, valid ESI (one CiA-402 drive) written from parameters, for bad-input tests."""

from __future__ import annotations

OBJECTS = [
    # index, name, type, bits, PdoMapping flag
    (0x6040, "Controlword", "UINT", 16, "R"),
    (0x6060, "Modes of operation", "SINT", 8, "R"),
    (0x607A, "Target position", "DINT", 32, "R"),
    (0x6071, "Target torque", "INT", 16, "R"),
    (0x6041, "Statusword", "UINT", 16, "T"),
    (0x6064, "Position actual value", "DINT", 32, "T"),
    (0x606C, "Velocity actual value", "DINT", 32, "T"),
    (0x6077, "Torque actual value", "INT", 16, "T"),
]


def entry(index: int, bits: int, sub: int = 0, number: str = "hex") -> str:
    idx = f"#x{index:04X}" if number == "hex" else str(index)
    return (
        f"<Entry><Index>{idx}</Index><SubIndex>{sub}</SubIndex><BitLen>{bits}</BitLen>"
        "<Name>x</Name></Entry>"
    )


def esi(
    rx_entries: str | None = None,
    tx_entries: str | None = None,
    sm_max: int = 64,
    modes: str = "AD030000",  # 0x3AD little-endian: pp, pv, tq, hm, csp, csv, cst
    number: str = "hex",
    extra_device: bool = False,
    prolog: str = '<?xml version="1.0" encoding="utf-8"?>\n',
    coe: str = 'PdoAssign="1" PdoConfig="1"',
) -> str:
    h = (lambda v, w=4: f"#x{v:0{w}X}") if number == "hex" else (lambda v, w=4: str(v))
    rx = rx_entries if rx_entries is not None else (
        entry(0x6040, 16, number=number) + entry(0x607A, 32, number=number)
        + entry(0x6071, 16, number=number) + entry(0x6060, 8, number=number) + entry(0, 8)
    )  # fmt: skip
    tx = tx_entries if tx_entries is not None else (
        entry(0x6041, 16, number=number) + entry(0x6064, 32, number=number)
        + entry(0x606C, 32, number=number) + entry(0x6077, 16, number=number)
    )  # fmt: skip
    objects = "".join(
        f"<Object><Index>{h(i)}</Index><Name>{n}</Name><Type>{t}</Type><BitSize>{b}</BitSize>"
        f"<Flags><Access>rw</Access><PdoMapping>{f}</PdoMapping></Flags></Object>"
        for i, n, t, b, f in OBJECTS
    ) + (
        f"<Object><Index>{h(0x6502)}</Index><Name>Supported drive modes</Name><Type>UDINT</Type>"
        f"<BitSize>32</BitSize><Info><DefaultData>{modes}</DefaultData></Info></Object>"
    )
    device = (
        f'<Device><Type ProductCode="{h(0x1234, 8)}" RevisionNo="{h(2, 8)}">Test Drive</Type>'
        "<Name>Test Drive</Name>"
        "<Profile><ProfileNo>402</ProfileNo><Dictionary><DataTypes/>"
        f"<Objects>{objects}</Objects></Dictionary></Profile>"
        '<Sm StartAddress="#x1000" ControlByte="#x26" Enable="1">MBoxOut</Sm>'
        '<Sm StartAddress="#x1080" ControlByte="#x22" Enable="1">MBoxIn</Sm>'
        f'<Sm MaxSize="{sm_max}" StartAddress="#x1100" ControlByte="#x64" Enable="1">Outputs</Sm>'
        f'<Sm MaxSize="{sm_max}" StartAddress="#x1180" ControlByte="#x20" Enable="1">Inputs</Sm>'
        f'<RxPdo Fixed="1" Sm="2"><Index>{h(0x1600)}</Index><Name>Rx</Name>{rx}</RxPdo>'
        f'<TxPdo Fixed="1" Sm="3"><Index>{h(0x1A00)}</Index><Name>Tx</Name>{tx}</TxPdo>'
        f"<Mailbox><CoE {coe}><InitCmd><Transition>PS</Transition><Index>#x60C2</Index>"
        "<SubIndex>1</SubIndex><Data>01</Data><Comment>period</Comment></InitCmd></CoE></Mailbox>"
        "<Dc><OpMode><Name>DC</Name><AssignActivate>#x300</AssignActivate>"
        "<CycleTimeSync0>0</CycleTimeSync0><ShiftTimeSync0>0</ShiftTimeSync0></OpMode></Dc>"
        "</Device>"
    )
    second = device.replace("Test Drive", "Other Drive").replace(h(0x1234, 8), h(0x1235, 8))
    return (
        f"{prolog}<EtherCATInfo><Vendor><Id>{h(0x99, 8)}</Id><Name>Test Vendor</Name></Vendor>"
        "<Descriptions><Groups><Group><Type>Drives</Type></Group></Groups><Devices>"
        f"{device}{second if extra_device else ''}</Devices></Descriptions></EtherCATInfo>\n"
    )
