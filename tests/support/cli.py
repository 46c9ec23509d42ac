"""The CLI tests' check of a user error: exit code 2 and one line, never a traceback."""

from __future__ import annotations


def one_line_error(code: int, err: str, *needles: str) -> str:
    """Assert ``code`` is 2 and ``err`` is one line without a traceback that contains every
    one of ``needles``; returns that line."""
    assert code == 2, err
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    for needle in needles:
        assert needle in lines[0], (needle, err)
    return lines[0]


def run_limited(
    argv: list[str],
    *,
    timeout: float = 20.0,
    memory: int = 2 << 30,
    cwd: str | None = None,
    read_only: str | None = None,
) -> tuple[int | None, str, str, float]:
    """Run ``hofto-hw ARGV`` in a subprocess under an address-space limit of ``memory``
    bytes (RLIMIT_AS) and a wall-clock ``timeout`` [s]: for inputs that used to hang or
    exhaust memory. ``read_only``: a folder the command sees as a read-only mount (a
    private mount namespace, ``unshare``; needs root, see :func:`read_only_reason`).
    Returns (exit code, or None when it was killed at the timeout, stdout, stderr, seconds
    taken)."""
    import resource
    import subprocess
    import sys
    import time

    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (memory, memory))

    code = f"import sys; from hofto_hw.cli import main; sys.exit(main({argv!r}))"
    cmd = [sys.executable, "-c", code]
    if read_only is not None:
        script = 'mount --bind "$1" "$1" && mount -o remount,bind,ro "$1" && shift && exec "$@"'
        cmd = ["unshare", "--mount", "--propagation", "private", "sh", "-c", script, "sh"]
        cmd += [read_only, *([sys.executable, "-c", code])]
    t0 = time.monotonic()
    try:
        p = subprocess.run(
            cmd,
            capture_output=True,
            text=True,
            timeout=timeout,
            preexec_fn=limit,
            cwd=cwd,
        )
    except subprocess.TimeoutExpired as exc:
        out = exc.stdout.decode() if isinstance(exc.stdout, bytes) else (exc.stdout or "")
        err = exc.stderr.decode() if isinstance(exc.stderr, bytes) else (exc.stderr or "")
        return None, out, err, time.monotonic() - t0
    return p.returncode, p.stdout, p.stderr, time.monotonic() - t0


def read_only_reason() -> str | None:
    """Why :func:`run_limited` cannot give a read-only mount here (None: it can). Under
    ``CI`` (root) it must: the caller fails instead of skipping."""
    import os
    import shutil

    if os.geteuid() != 0:
        return "a read-only mount needs root (unshare --mount); CI runs as root"
    if shutil.which("unshare") is None:
        return "no unshare(1) to make a read-only mount"
    return None
