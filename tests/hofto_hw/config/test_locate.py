"""config.locate.output_folder: where a config's relative output folder (run.log_dir) lands."""

from __future__ import annotations

from pathlib import Path

import pytest

from hofto_hw.config import locate


@pytest.fixture
def installed(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """Shipped configs as an installed wheel holds them (site-packages/hofto_hw/robot_configs),
    the working directory an empty folder elsewhere; returns that folder."""
    shipped = tmp_path / "site-packages" / "hofto_hw" / "robot_configs"
    (shipped / "er3a").mkdir(parents=True)
    monkeypatch.setattr(locate, "PROJECT_CONFIGS", shipped)
    monkeypatch.setattr(locate, "SHIPPED_IN_PACKAGE", True)
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    return work


def test_a_shipped_config_of_an_installed_wheel_writes_under_the_working_directory(
    installed: Path,
) -> None:
    shipped = locate.PROJECT_CONFIGS
    logs = locate.output_folder(Path("../out/logs"), shipped / "er3a.yaml")
    assert logs == installed / "out" / "logs"
    assert not logs.is_relative_to(shipped.parent)  # nothing written into the package
    # a config in a folder of the shipped ones keeps its place below ./configs
    assert locate.output_folder(Path("logs"), shipped / "er3a" / "x.yaml") == (
        installed / "configs" / "er3a" / "logs"
    )


def test_a_users_config_writes_beside_itself_and_an_absolute_folder_is_kept(
    installed: Path, tmp_path: Path
) -> None:
    mine = tmp_path / "cell" / "configs" / "er3a.yaml"
    assert locate.output_folder(Path("../out/logs"), mine) == tmp_path / "cell" / "out" / "logs"
    assert locate.output_folder(Path("/var/log/hofto-hw"), mine) == Path("/var/log/hofto-hw")
    shipped = locate.PROJECT_CONFIGS / "er3a.yaml"
    assert locate.output_folder(Path("/var/log/x"), shipped) == Path("/var/log/x")


def test_a_checkouts_configs_write_beside_the_checkout(
    installed: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A checkout's configs/ is the project's own folder: out/ beside it, wherever the command
    runs."""
    monkeypatch.setattr(locate, "SHIPPED_IN_PACKAGE", False)
    shipped = locate.PROJECT_CONFIGS
    logs = locate.output_folder(Path("../out/logs"), shipped / "er3a.yaml")
    assert logs == shipped.parent / "out" / "logs"
