"""Output files a user names: checked before the work they follow, written atomically.

One helper for every output of the stack (``-o``, ``--plot``, ``--summary-json``, ``log
recover``'s output, ``mode drag --record``, parameters and thresholds files):

- :func:`output_problem` / :func:`check_output`: the name is not a folder, its folder
  exists, is a folder and takes a new file (probed by creating and removing a hidden
  temporary file there: ``os.access`` says yes to root in a read-only place, in /proc or on
  a read-only mount), an existing file at that name is a regular file (not a device, a FIFO
  or a /proc entry) and is not one of the command's inputs. Called before the work.
- :func:`atomic_path` / :func:`write_atomic`: the content goes to a temporary file in the
  same folder, then ``os.replace`` puts it at the name: a failure (disk full, killed) leaves
  the old file, or none, never half a file. Their failure handlers cannot fail again: the
  cleanup of the temporary file ignores its own errors.

Foundation: the errors module only. Nothing here runs in the tick.
"""

from __future__ import annotations

import contextlib
import os
import stat
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path

from hofto_hw.errors import UserError


def output_problem(path: Path | str, *, replace: bool = True) -> str | None:
    """Why ``path`` cannot be written as a new or replaced file, or None when it can.

    ``replace`` False: an existing file is a problem too. The reason reads after the name
    (``"PATH: " + reason``).
    """
    text = str(path)
    path = Path(path)
    if not text or text.endswith(("/", os.sep)) or path.is_dir():
        return "is a folder; give a file name"
    try:
        st = os.lstat(path)
    except (FileNotFoundError, NotADirectoryError):  # the folder check below says which
        st = None
    except OSError as exc:
        return f"cannot be checked: {exc.strerror}"
    if st is not None:
        if stat.S_ISLNK(st.st_mode):
            try:
                st = os.stat(path)
            except OSError:
                return "is a dangling symbolic link"
        if not stat.S_ISREG(st.st_mode):
            return "exists and is not a regular file"
        if not replace:
            return "exists; not overwriting it (name a new file)"
    folder = path.parent
    if not folder.is_dir():
        what = "is not a folder" if folder.exists() else "does not exist"
        return f"folder {str(folder)!r} {what} (create it first)"
    return _probe(folder)


def _probe(folder: Path) -> str | None:
    """Create and remove a hidden file in ``folder``: None, or why that failed."""
    try:
        fd, name = tempfile.mkstemp(prefix=".hofto-hw-probe-", dir=folder)
    except OSError as exc:
        return f"folder {str(folder)!r} is not writable ({exc.strerror or exc})"
    os.close(fd)
    with contextlib.suppress(OSError):
        os.unlink(name)
    return None


def check_output(
    path: Path | str,
    option: str,
    *,
    inputs: Iterable[Path | str | None] = (),
    replace: bool = True,
) -> Path:
    """Raise :class:`UserError` (``OPTION PATH: reason``) unless ``path`` can be written and
    is none of ``inputs`` (an input named ``FILE@ROWS`` counts as FILE). Returns the path."""
    path = Path(path)
    problem = output_problem(path, replace=replace)
    if problem is None and path.exists():
        for item in inputs:
            if item is None:
                continue
            src = Path(str(item).rsplit("@", 1)[0])
            if src.exists() and os.path.samefile(src, path):
                problem = "is an input of this command; refusing to overwrite"
                break
    if problem is not None:
        raise UserError(f"{option} {path}: {problem}".lstrip())
    return path


@contextlib.contextmanager
def atomic_path(path: Path | str, what: str) -> Iterator[Path]:
    """A temporary file beside ``path`` to write; on a clean exit it replaces ``path``
    (``os.replace``), on an error it is removed. An OSError becomes one line,
    ``PATH: cannot write WHAT: reason`` (UserError)."""
    path = Path(path)
    try:
        fd, name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".partial", dir=path.parent)
    except OSError as exc:
        raise _write_error(path, what, exc) from None
    os.close(fd)
    tmp = Path(name)
    try:
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # what open() would have made, not mkstemp's 0600
        yield tmp
        os.replace(tmp, path)
    except OSError as exc:
        _remove(tmp)
        raise _write_error(path, what, exc) from None
    except BaseException:
        _remove(tmp)
        raise


def write_atomic(path: Path | str, data: str | bytes, what: str) -> Path:
    """Write ``data`` (text is UTF-8) to ``path`` through :func:`atomic_path`, synced to disk
    before the rename. Returns the path."""
    raw = data.encode("utf-8") if isinstance(data, str) else data
    with atomic_path(path, what) as tmp, open(tmp, "wb") as f:
        f.write(raw)
        f.flush()
        os.fsync(f.fileno())
    return Path(path)


def _write_error(path: Path, what: str, exc: OSError) -> UserError:
    return UserError(f"{path}: cannot write {what}: {exc.strerror or exc}")


def _remove(path: Path) -> None:
    """Remove ``path`` if it is there; never raises (a failure handler must not fail)."""
    with contextlib.suppress(OSError):
        os.unlink(path)
