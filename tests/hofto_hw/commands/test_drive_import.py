"""``hofto-hw drive import``: what it prints and writes, and its one-line refusals (exit 2,
nothing written); ``config check`` of a config that names a profile."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from hofto_hw.cli import main
from hofto_hw.config.drive_profile import load_profile
from tests.support.esi_factory import esi

ROOT = Path(__file__).resolve().parents[3]
DATA = ROOT.parent / "shared" / "data" / "drives"
ER3A = ROOT / "configs" / "er3a.yaml"


def _run(capsys, *argv: str) -> tuple[int, str, str]:
    code = main(["drive", "import", *argv])
    out = capsys.readouterr()
    return code, out.out, out.err.strip()


def _refused(capsys, *argv: str) -> str:
    code, _, err = _run(capsys, *argv)
    assert code == 2 and len(err.splitlines()) == 1 and "Traceback" not in err, err
    return err


@pytest.fixture()
def esi_file(tmp_path: Path) -> Path:
    path = tmp_path / "drive.xml"
    path.write_text(esi())
    return path


def test_import_prints_choice_and_writes_profile(tmp_path, esi_file, capsys):
    out = tmp_path / "test_drive.yaml"
    code, text, err = _run(capsys, str(esi_file), "-o", str(out))
    assert code == 0, err
    assert "Test Drive -> profile test_drive (ethercat)" in text
    assert "rx: fixed 0x1600" in text and "dc: op mode 'DC'" in text
    assert (
        "rx 0x1600 (fixed, 10 bytes): controlword, target_position, target_torque, mode, pad8"
        in text
    )
    profile = load_profile(out)
    assert profile.name == "test_drive" and profile.source.file == "drive.xml"
    assert out.read_text().startswith("# drive profile written by `hofto-hw drive import")


def test_import_without_output_prints_yaml(esi_file, capsys):
    code, text, _ = _run(capsys, str(esi_file))
    assert code == 0 and "profile: 1\n" in text and "index: 0x6040" in text


def test_json(tmp_path, esi_file, capsys):
    code, text, _ = _run(capsys, str(esi_file), "--json")
    assert code == 0
    doc = json.loads(text)
    assert set(doc) == {"file", "device", "profile", "reasons", "written"}
    assert doc["profile"]["rx_pdos"][0]["index"] == 0x1600 and doc["written"] is None


def test_output_is_checked_before_the_work(tmp_path, esi_file, capsys):
    before = esi_file.read_bytes()
    err = _refused(capsys, str(esi_file), "-o", str(esi_file))
    assert "is an input of this command" in err and esi_file.read_bytes() == before
    err = _refused(capsys, str(esi_file), "-o", str(tmp_path / "nosuch" / "p.yaml"))
    assert "nosuch" in err
    err = _refused(capsys, str(esi_file), "-o", str(tmp_path / "p.txt"))
    assert "a drive profile is a .yaml file" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["drive.xml"]


def test_several_devices_ask_for_device(tmp_path, capsys):
    path = tmp_path / "two.xml"
    path.write_text(esi(extra_device=True))
    err = _refused(capsys, str(path))
    assert "describes 2 drives; choose one with --device" in err
    assert "[1] Test Drive (0x1234:0x2)" in err and "[2] Other Drive (0x1235:0x2)" in err
    for selector, name in (
        ("2", "Other Drive"),
        ("test drive", "Test Drive"),
        ("0x1235", "Other Drive"),
        ("0x1234:2", "Test Drive"),
    ):
        code, text, _ = _run(capsys, str(path), "--device", selector)
        assert code == 0 and f"{name} -> profile" in text, selector
    assert "matches none" in _refused(capsys, str(path), "--device", "nothing")
    assert "matches 2" in _refused(capsys, str(path), "--device", "drive")


@pytest.mark.parametrize(
    ("text", "expect"),
    [
        (esi()[:300], "truncated"),
        ('<?xml version="1.0"?><!DOCTYPE a [<!ENTITY a "aaaa">]><EtherCATInfo/>', "DOCTYPE"),
        ("not a vendor file\n", "neither XML (ESI) nor INI"),
        (esi(modes="01000000"), "no cyclic synchronous mode"),
        (esi().replace("Controlword", "x").replace("#x6040", "#x2040"), "no CiA-402 drive"),
    ],
)
def test_bad_input_writes_nothing(tmp_path, capsys, text, expect):
    path = tmp_path / "bad.xml"
    path.write_text(text)
    out = tmp_path / "p.yaml"
    assert expect in _refused(capsys, str(path), "-o", str(out))
    assert not out.exists()


def test_loop_option(esi_file, capsys):
    code, text, _ = _run(capsys, str(esi_file), "--loop", "cst")
    assert code == 0 and "loop: cst" in text
    bad = esi_file.with_name("pp.xml")
    bad.write_text(esi(modes="81000000"))  # pp, csp
    assert "--loop cst: the drive supports pp, csp" in _refused(capsys, str(bad), "--loop", "cst")


EXPECTED = {
    "elmo_GoldDrive.xml": (["--device", "0x30924:0x10420"], 0, "Elmo Drive -> profile"),
    "inovance_SV660N.xml": ([], 0, "configurable 0x1600"),
    "nanotec_C5-E-2-21.xml": ([], 0, "AssignActivate 0x0330, SYNC0 fixed at 1000000 ns"),
    "synapticon_SOMANET-Node-fw5.6.6.xml": (["--device", "SOMANET Node"], 0, "0x6502 = 0x303AD"),
    "maxon_EPOS4-Micro-24-5_IgH-SII-dump_NOT-VENDOR-ESI.xml": ([], 0, "SII dump"),
    "zeroerr_eRob-eDriver.eds": ([], 0, "bitrates 1000 kbit/s"),
    "itegva_E7x-IO_NEGATIVE.xml": ([], 2, "no CiA-402 drive described"),
    "faulhaber_MCBL300x-CO.eds": ([], 0, "loop: pv (profile velocity, 0x6060 = 3) streamed"),
    "technosoft_iPOS.eds": ([], 0, "loop: ip (interpolated position, 0x6060 = 7)"),
}


@pytest.mark.data
@pytest.mark.skipif(not DATA.is_dir(), reason="../shared/data/drives (vendor files) absent")
@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_every_vendor_file(tmp_path, capsys, name):
    extra, want_code, want_text = EXPECTED[name]
    out = tmp_path / "p.yaml"
    code, text, err = _run(capsys, str(DATA / name), *extra, "-o", str(out))
    assert code == want_code, err
    assert want_text in (text if code == 0 else err)
    assert out.exists() == (code == 0)
    if code == 2:
        assert len(err.splitlines()) == 1


def _config(tmp_path: Path, profile: str, rate: str = "1000.0") -> Path:
    text = ER3A.read_text().replace("urdf: er3a/er3a.urdf", f"urdf: {ER3A.parent}/er3a/er3a.urdf")
    text = text.replace("rate_hz: 1000.0", f"rate_hz: {rate}")
    old = "identity: {vendor_id: 0x00000DEC, product_code: 0x00402001}}"
    text = text.replace(old, f"profile: {profile}}}", 1)  # the profile's identity
    path = tmp_path / "cfg.yaml"
    path.write_text(text)
    return path


def test_config_check_loads_the_named_profile(tmp_path, capsys):
    code = main(["config", "check", str(_config(tmp_path, "nanotec_c5_e_2_21"))])
    assert code == 0, capsys.readouterr().err
    capsys.readouterr()
    assert main(["config", "check", str(_config(tmp_path, "nanotec_c5_e_2_21", "500.0"))]) == 2
    err = capsys.readouterr().err.strip()
    assert (
        "bus.drives[0].profile 'nanotec_c5_e_2_21': profile nanotec_c5_e_2_21: dc.sync0_cycle_ns"
        in err
    )
    assert main(["config", "check", str(_config(tmp_path, "no_such_drive"))]) == 2
    assert "drive profile 'no_such_drive' is neither a file" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("change", "expect"),
    [
        (lambda d: d["rx_pdos"][0]["entries"].append(dict(d["rx_pdos"][0]["entries"][0])),
         "mapped twice"),
        (lambda d: d["rx_pdos"][0]["entries"].append({"index": 0, "bits": 4}),
         "not a whole number of bytes"),
        (lambda d: d["dc"].update(sync0_cycle_ns=2_000_000), "not the loop's period"),
    ],
)  # fmt: skip
def test_config_check_refuses_a_bad_profile(tmp_path, capsys, change, expect):
    import yaml

    data = yaml.safe_load((ROOT / "configs" / "drives" / "nanotec_c5_e_2_21.yaml").read_text())
    change(data)
    (tmp_path / "bad.yaml").write_text(yaml.safe_dump(data))
    assert main(["config", "check", str(_config(tmp_path, "bad.yaml"))]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and expect in err and "bad.yaml" in err, err
