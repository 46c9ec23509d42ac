"""Drive profile files: find one by name (``configs/drives/<name>.yaml``) or path, load and
validate it, resolve the profiles a config names, write one (YAML, hex indices, atomically)."""

from __future__ import annotations

from pathlib import Path

from pydantic import ValidationError

from hofto_hw.config.drive_profile.schema import DriveProfile, check_profile_against_loop
from hofto_hw.config.drives import BusConfig
from hofto_hw.config.loader import read_yaml
from hofto_hw.config.locate import config_dirs, named_yaml
from hofto_hw.errors import ConfigError


def profile_dirs() -> list[Path]:
    """Folders searched for ``<name>.yaml`` by profile name: ./configs/drives, then the
    project's configs/drives."""
    return [d / "drives" for d in config_dirs()]


def find_profile(spec: str | Path, base_dir: Path | None = None) -> Path:
    """The profile file named by ``spec``: a path (relative to ``base_dir`` when given) or a
    profile name in configs/drives/.

    Raises:
        ConfigError: naming what was looked for and the profiles that exist.
    """
    path = Path(spec)
    candidates = [path] if path.is_absolute() or base_dir is None else [base_dir / path, path]
    for c in candidates:
        if c.is_file():
            return c
    name = str(spec)
    if "/" in name or path.suffix in (".yaml", ".yml"):
        raise ConfigError(f"{candidates[0]}: drive profile not found")
    found, known = named_yaml(name, profile_dirs())
    if found is not None:
        return found
    raise ConfigError(
        f"drive profile {name!r} is neither a file nor a profile in configs/drives/ (have: "
        f"{', '.join(known) or 'none'})"
    )


def format_profile_error(source: str, err: ValidationError) -> str:
    """``format_validation_error`` for profiles: a cross-field check (a ``ValueError`` of a
    model validator) reads ``FILE: field: message`` without the whole section as "got"."""
    lines = []
    for e in err.errors(include_url=False):
        loc = ".".join(f"[{p}]" if isinstance(p, int) else str(p) for p in e.get("loc", ()))
        loc = loc.replace(".[", "[")
        msg = e.get("msg", "invalid")
        got = e.get("input")
        if e.get("type") == "value_error":
            msg = msg.removeprefix("Value error, ")
        shown = "" if isinstance(got, dict | list) else f" (got {got!r:.80})"
        lines.append(f"{source}: {loc + ': ' if loc else ''}{msg}{shown}")
    return "\n".join(lines)


def parse_profile(data: object, source: str) -> DriveProfile:
    """Validate an already-parsed profile mapping; errors as :func:`format_profile_error`."""
    try:
        return DriveProfile.model_validate(data)
    except ValidationError as err:
        raise ConfigError(format_profile_error(source, err)) from None


def load_profile(path: str | Path) -> DriveProfile:
    """Read and validate the drive profile file ``path`` (YAML).

    Raises:
        ConfigError: one line per problem, ``FILE: field.path: message (got VALUE)``.
    """
    return parse_profile(read_yaml(path, "drive profile"), str(path))


def resolve_profiles(
    bus: BusConfig, cycle_time: float, source: str, base_dir: Path | None = None
) -> list[DriveProfile | None]:
    """Load the profile each of ``bus.drives`` names (None where it names none), check each
    against the bus kind and the loop period ``cycle_time`` [s].

    ``source`` is the config file's name, ``base_dir`` its folder (relative profile paths).

    Raises:
        ConfigError: one line naming ``bus.drives[i].profile`` and what is wrong.
    """
    kind = {"ethercat": "ethercat", "canopen": "canopen"}.get(bus.transport)
    loaded: dict[Path, DriveProfile] = {}
    out: list[DriveProfile | None] = []
    for i, drive in enumerate(bus.drives):
        if drive.profile is None:
            out.append(None)
            continue
        where = f"{source}: bus.drives[{i}].profile {drive.profile!r}"
        try:
            path = find_profile(drive.profile, base_dir)
        except ConfigError as exc:
            raise ConfigError(f"{where}: {exc}") from None
        key = path.resolve()
        if key not in loaded:
            loaded[key] = load_profile(path)
        profile = loaded[key]
        if kind is not None and profile.bus != kind:
            raise ConfigError(
                f"{where}: profile {profile.name} is an {profile.bus} drive, the bus is "
                f"{bus.transport} (got {drive.profile!r})"
            )
        ident = drive.identity
        if "identity" in drive.model_fields_set and (
            ident.vendor_id != profile.identity.vendor_id
            or ident.product_code != profile.identity.product_code
        ):
            raise ConfigError(
                f"{where}: bus.drives[{i}].identity (vendor 0x{ident.vendor_id:08X}, product "
                f"0x{ident.product_code:08X}) is not the profile's drive (vendor "
                f"0x{profile.identity.vendor_id:08X}, product "
                f"0x{profile.identity.product_code:08X}): fix the identity or drop it (the "
                "profile's is used)"
            )
        check_profile_against_loop(profile, cycle_time, where)
        if drive.device_axis >= profile.axes:
            raise ConfigError(
                f"{where}: bus.drives[{i}].device_axis {drive.device_axis}: profile "
                f"{profile.name} has {profile.axes} axis(es), 0..{profile.axes - 1}"
            )
        out.append(profile)
    return out


#: keys whose integer values are written in hex (object indices, identity, DC word, COB-IDs)
_HEX_KEYS = {"index": 4, "vendor_id": 8, "product_code": 8, "revision_min": 8,
             "revision_max": 8, "assign_activate": 4, "cob_id_base": 3}  # fmt: skip


def profile_yaml(profile: DriveProfile, header: str = "") -> str:
    """The YAML text of ``profile``: indices and identities in hex (``0x6040``), fields in
    schema order, ``header`` as leading comment lines. :func:`load_profile` reads it back equal."""
    import yaml

    from hofto_hw.config.loader import NoAliasDumper

    class _Hex(int):
        width = 4

    class _Dumper(NoAliasDumper):
        pass

    def _hex(dumper: yaml.SafeDumper, value: _Hex) -> yaml.ScalarNode:
        return dumper.represent_scalar("tag:yaml.org,2002:int", f"0x{int(value):0{value.width}X}")

    _Dumper.add_representer(_Hex, _hex)

    def walk(node: object, key: str = "") -> object:
        if isinstance(node, dict):  # an entry's axis 0 is the default: not written
            return {k: walk(v, k) for k, v in node.items() if not (k == "axis" and v == 0)}
        if isinstance(node, list | tuple):
            return [walk(v, key) for v in node]
        if key in _HEX_KEYS and isinstance(node, int) and not isinstance(node, bool) and node >= 0:
            h = _Hex(node)
            h.width = _HEX_KEYS[key]
            return h
        return node

    data = walk(profile.model_dump(mode="python"))
    text = yaml.dump(data, Dumper=_Dumper, sort_keys=False, allow_unicode=True, width=100)
    lines = "".join(f"# {line}\n" if line else "#\n" for line in header.splitlines())
    return lines + text


def write_profile(profile: DriveProfile, path: str | Path, header: str = "") -> None:
    """Write ``profile`` to ``path`` atomically (a temporary file in the same folder, then a
    rename): a reader never sees half a profile, a failed write leaves the old file.

    Raises:
        ConfigError: the folder is missing or not writable (one line).
    """
    import os
    import tempfile

    path = Path(path)
    text = profile_yaml(profile, header)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
        os.replace(tmp, path)
    except OSError as exc:
        try:
            os.unlink(tmp)
        except (OSError, UnboundLocalError):
            pass
        raise ConfigError(f"{path}: cannot write drive profile: {exc.strerror or exc}") from None
