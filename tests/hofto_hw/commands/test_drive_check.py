"""``hofto-hw drive check``: every shipped drive profile brought up by the real master on
an emulated bus (EtherCAT on veth as root, CANopen on python-can's virtual bus, the ip and pv
profiles once over udp_multicast too), enabled,
moved 0.05 rad and back; bad input refused in one line."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml

from hofto_hw.cli import main

ROOT = Path(__file__).resolve().parents[3]
PROFILES = sorted((ROOT / "configs" / "drives").glob("*.yaml"))


def _bus(path: Path) -> str:
    return str(yaml.safe_load(path.read_text())["bus"])


ETHERCAT = [p for p in PROFILES if _bus(p) == "ethercat"]
CANOPEN = [p for p in PROFILES if _bus(p) == "canopen"]


def _check(capsys, *argv: str) -> tuple[int, dict]:
    code = main(["drive", "check", *argv, "--json"])
    out = capsys.readouterr().out
    return code, json.loads(out)


def _assert_passed(code: int, report: dict, axes: int = 6) -> None:
    assert report["faults"] == []
    assert report["operational"] and report["enabled"]
    assert report["axes"] == axes
    assert len(report["moved_rad"]) == axes
    assert all(abs(m - 0.05) <= 0.005 for m in report["moved_rad"]), report["moved_rad"]
    assert len(report["process_image_bytes"]) == axes
    assert all(b["rx"] > 0 and b["tx"] > 0 for b in report["process_image_bytes"])
    assert all(p["rx"] and p["tx"] for p in report["pdos"])
    assert report["passed"] and code == 0


@pytest.mark.parametrize("path", CANOPEN, ids=[p.stem for p in CANOPEN])
def test_canopen_profile_check_emulated(capsys, path: Path) -> None:
    code, report = _check(capsys, str(path), "--emulated")
    assert report["bus"] == "canopen"
    _assert_passed(code, report)
    prof = yaml.safe_load(path.read_text())
    assert report["pdos"][0]["rx"] == [f"0x{p['index']:04X}" for p in prof["rx_pdos"]]
    assert report["startup_sdos"] == 6 * len(prof.get("startup", []))


@pytest.mark.root
@pytest.mark.parametrize("path", ETHERCAT, ids=[p.stem for p in ETHERCAT])
def test_ethercat_profile_check_emulated(capsys, path: Path) -> None:
    from support.rootnet import require_root

    require_root()
    code, report = _check(capsys, str(path), "--emulated")
    assert report["bus"] == "ethercat"
    _assert_passed(code, report)
    prof = yaml.safe_load(path.read_text())
    assert report["pdos"][0]["tx"] == [f"0x{p['index']:04X}" for p in prof["tx_pdos"]]
    writes = [w for w in prof.get("startup", []) if w["transition"] in ("IP", "PS", "SO")]
    assert report["startup_sdos"] == 6 * len(writes)


@pytest.mark.parametrize("name", ["technosoft_ipos", "faulhaber_mcbl300x"])
def test_ip_and_pv_profiles_checked_over_udp_multicast(capsys, name: str) -> None:
    """The two drives without a cyclic synchronous mode (loop ip / pv) over UDP multicast:
    the emulated drives on their own group and port, in this process, no root."""
    path = ROOT / "configs" / "drives" / f"{name}.yaml"
    code, report = _check(capsys, str(path), "--emulated", "--can-interface", "udp_multicast")
    assert report["can_interface"] == "udp_multicast"
    assert report["loop"] == {"technosoft_ipos": "ip", "faulhaber_mcbl300x": "pv"}[name]
    _assert_passed(code, report)
    prof = yaml.safe_load(path.read_text())
    assert report["startup_sdos"] == 6 * len(prof.get("startup", []))
    # configure ran and left out what the drive lacks (0x6072 ...), one line per axis
    assert len(report["settings"]) == 6
    assert report["settings"][0].startswith(f"axis 0 (joint_1, {name}): no 0x6072 max_torque")


def test_canopen_check_on_fewer_axes_reports_those(capsys) -> None:
    code, report = _check(capsys, str(CANOPEN[0]), "--emulated", "--axes", "2")
    _assert_passed(code, report, axes=2)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["no_such_profile", "--emulated"], "no_such_profile"),
        ([str(CANOPEN[0]) if CANOPEN else "x", "--iface", "eth0"], "--iface is for EtherCAT"),
        ([str(ETHERCAT[0]) if ETHERCAT else "x", "--interface", "socketcan"], "--channel"),
        ([str(CANOPEN[0]) if CANOPEN else "x", "--emulated", "--axes", "7"], "--axes 7"),
        ([str(CANOPEN[0]) if CANOPEN else "x", "--emulated", "--move", "2"], "--move 2"),
        (
            [str(ETHERCAT[0]) if ETHERCAT else "x", "--emulated", "--can-interface", "virtual"],
            "--can-interface goes with --emulated and a CANopen profile",
        ),
        (
            [str(ETHERCAT[0]) if ETHERCAT else "x", "--emulated", "--slaves", "1"],
            "--slaves goes with --iface",
        ),
        (
            [str(ETHERCAT[0]) if ETHERCAT else "x", "--iface", "eth0", "--slaves", "0,2"],
            "--slaves 0,2: distinct line positions from 1",
        ),
        (
            [str(ETHERCAT[0]) if ETHERCAT else "x", "--iface", "eth0", "--slaves", "1,1"],
            "--slaves 1,1: distinct line positions from 1",
        ),
        (
            [str(ETHERCAT[0]) if ETHERCAT else "x", "--iface", "eth0", "--slaves", "one"],
            "--slaves one: line positions from 1",
        ),
        (
            [
                str(ETHERCAT[0]) if ETHERCAT else "x",
                "--iface",
                "eth0",
                "--slaves",
                "1,3",
                "--axes",
                "1",
            ],
            "--axes 1 does not fit --slaves 1,3",
        ),
        (
            [str(ETHERCAT[0]) if ETHERCAT else "x", "--iface", "eth0", "--slaves", "7"],
            "has 6 drives (bus.drives, in line order); slave 7 has none",
        ),
    ],
)
def test_bad_input_is_one_line_exit_2(capsys, argv: list[str], message: str) -> None:
    code = main(["drive", "check", *argv])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert message in err and "\n" not in err and "Traceback" not in err


FAULHABER = ROOT / "configs" / "drives" / "faulhaber_mcbl300x.yaml"
REFUSED = (
    "joint_1 (faulhaber_mcbl300x): the drive's velocity unit is not stated in its file; set "
    "units.velocity in the profile (counts/s or rpm) after checking the drive's manual"
)


def test_unknown_velocity_unit_runs_emulated_in_counts_and_says_so(capsys) -> None:
    """The shipped Faulhaber profile does not know its velocity unit: the emulated check runs
    the emulator in counts/s and says so in one line (stderr and the report's warnings)."""
    assert yaml.safe_load(FAULHABER.read_text())["units"]["velocity"] == "unknown"
    code = main(["drive", "check", str(FAULHABER), "--emulated", "--json"])
    captured = capsys.readouterr()
    report = json.loads(captured.out)
    _assert_passed(code, report)
    note = [w for w in report["warnings"] if "velocity unit unknown" in w]
    assert len(note) == 1 and "runs in counts/s" in note[0]
    assert captured.err.strip() == f"note: {note[0]}"


def test_unknown_velocity_unit_refused_on_a_real_bus(capsys) -> None:
    """Not emulated: the CANopen master refuses the axis in one line before it opens the bus
    (python-can's virtual interface stands for the real one: nothing answers on it)."""
    code = main(["drive", "check", str(FAULHABER), "--interface", "virtual", "--channel", "x"])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert err.endswith(REFUSED) and "\n" not in err


def test_faulhaber_in_rpm_checked_emulated(capsys, tmp_path: Path) -> None:
    """A copy of the Faulhaber profile stating rpm and rpm/s: master and emulator convert in
    drivers/, the arm moves 0.05 rad on every axis with no fault and no units note."""
    prof = yaml.safe_load(FAULHABER.read_text())
    prof["units"].update(velocity="rpm", acceleration="rpm/s")
    path = tmp_path / "faulhaber_mcbl300x.yaml"
    path.write_text(yaml.safe_dump(prof, sort_keys=False))
    code, report = _check(capsys, str(path), "--emulated")
    _assert_passed(code, report)
    assert not any("velocity unit" in w for w in report["warnings"])
