"""Where the project's files are found: a robot config by path or robot name.

One resolver for every command: ``--config`` takes a path (``configs/ur10e.yaml``) or a robot
name (``ur10e`` -> ``configs/ur10e.yaml``); without it, the config of a parameters file's
robot is ``<robot>.yaml`` in that file's folder, the folder above, or ``configs/``.

The shipped configs (the project's ``configs/`` folder) are package data: an installed wheel
holds them as ``hofto_hw/robot_configs`` (setup.py maps the folder there); a source checkout,
editable or not installed, reads ``configs/`` beside the package.
"""

from __future__ import annotations

from pathlib import Path

from hofto_hw.errors import UserError


def _shipped_configs() -> Path:
    """The shipped configs: the installed package's data, else the checkout's configs/."""
    package = Path(__file__).resolve().parents[1]
    installed = package / "robot_configs"
    return installed if installed.is_dir() else package.parent / "configs"


#: the configs shipped with the project (see the module docstring)
PROJECT_CONFIGS = _shipped_configs()
#: whether they are the installed package's data (a wheel) rather than a checkout's configs/
SHIPPED_IN_PACKAGE = PROJECT_CONFIGS.name == "robot_configs"


def output_folder(value: Path, config: Path) -> Path:
    """A folder a config names for output (``run.log_dir``), made absolute.

    A relative value is taken from the config file's folder, as every path in a config is,
    except in a config read from the installed package's data (a robot name after a wheel
    install): the installed package is no place to write to, so there the working directory
    stands in for the project and the config counts as being in its ``configs/`` (the shipped
    ``../out/logs`` is ``./out/logs``, as it is when run from a checkout's root).
    """
    if value.is_absolute():
        return value
    base = config.resolve().parent
    if SHIPPED_IN_PACKAGE and base.is_relative_to(PROJECT_CONFIGS):
        base = Path.cwd() / "configs" / base.relative_to(PROJECT_CONFIGS)
    return (base / value).resolve()


def config_dirs() -> list[Path]:
    """Folders searched for ``<robot>.yaml`` by name: ./configs, then the project's."""
    local = Path("configs")
    dirs = [local]
    if not (local.is_dir() and local.resolve() == PROJECT_CONFIGS):
        dirs.append(PROJECT_CONFIGS)
    return dirs


def named_yaml(name: str, folders: list[Path]) -> tuple[Path | None, list[str]]:
    """``<name>.yaml`` in the first of ``folders`` that has it (None if none does), and the
    names every folder offers (sorted; for the message when it is not found)."""
    for folder in folders:
        candidate = folder / f"{name}.yaml"
        if candidate.is_file():
            return candidate, []
    return None, sorted({p.stem for d in folders for p in d.glob("*.yaml")})


def find_config(
    spec: str | Path | None,
    robot: str | None = None,
    near: Path | None = None,
    option: str = "--config",
) -> Path:
    """The config file named by ``spec`` (a path or a robot name), else the one of ``robot``.

    Args:
        spec: ``--config`` as given: an existing file, or a robot name; None to look up
            ``robot`` instead.
        robot: the robot name of a parameters/thresholds file (used when ``spec`` is None).
        near: the folder of that file: ``<robot>.yaml`` there or one folder up comes first.
        option: how the user gave ``spec``, for the error message.

    Raises:
        UserError: naming what was looked for and where.
    """
    if spec is not None:
        path = Path(spec)
        if path.is_file():
            return path
        if path.exists() and not path.is_dir():
            return path  # a FIFO, a device: the safe reader (loader.read_bounded) names what it is
        if path.is_dir():
            raise UserError(f"{option}: {path} is a folder, not a config file")
        name = str(spec)
        if "/" in name or path.suffix in (".yaml", ".yml"):
            raise UserError(f"{option}: {path}: config file not found")
        found, known = named_yaml(name, config_dirs())
        if found is not None:
            return found
        raise UserError(
            f"{option}: {name!r} is neither a file nor a known robot (have: "
            f"{', '.join(known) or 'none'})"
        )
    if robot is None:
        raise UserError("--config: give a config file or a robot name")
    folders = [near, near.parent] if near is not None else []
    for folder in [*folders, *config_dirs()]:
        candidate = folder / f"{robot}.yaml"
        if candidate.is_file():
            return candidate
    where = f"next to {near} or " if near is not None else ""
    raise UserError(
        f"unknown robot {robot!r}: no {robot}.yaml {where}in configs/; pass --config FILE"
    )
