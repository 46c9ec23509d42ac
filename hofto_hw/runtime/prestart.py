"""Helper processes of ``hofto-hw run`` started before their arguments exist.

The flight recorder's writer and the control plane run in processes of their own (nothing but
the loop runs Python in the loop's process). Each needs seconds to import numpy, numba,
pinocchio and our modules on a loaded machine, and its arguments (the config, the shared
memory's name, the listening socket) exist only after the loop's process has done the same.
So the run starts them first (:class:`Prestarted`, ``python -m hofto_hw.runtime.prestart
MODULE``): each imports ``MODULE`` (and whatever its ``preload()`` imports) while the loop's
process imports and reads the config, then waits for its arguments. :meth:`Prestarted.send`
hands them over (pickled on stdin; file descriptors over a socket pair, SCM_RIGHTS) and the
child calls ``MODULE.child_main(args, fds, term)``; :meth:`Prestarted.abandon` ends one that
will never get them (a refused config, a stop during the start-up): it holds nothing yet.

In the child, from its first line: SIGINT is ignored (the loop's, e.g. Ctrl-C to the process
group) and SIGTERM only noted (``term[0]``, the monotonic time; each child's own grace period
counts from it): the loop's process decides when its helpers end. An empty stdin (the parent
gave up or died before sending) ends the child silently with exit 0.

A further helper is one more ``Prestarted("package.module")`` in hofto_hw.commands.run's
:class:`~hofto_hw.commands.run.Helpers` and a ``child_main(args, fds, term)`` in its module.
"""

from __future__ import annotations

import os
import pickle
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

#: the folder holding this hofto_hw (put first on the children's PYTHONPATH)
_ROOT = str(Path(__file__).resolve().parents[2])
#: the most descriptors one child receives
MAX_FDS = 4


def child_env() -> dict[str, str]:
    """Our environment with this hofto_hw's folder first on PYTHONPATH, so a child runs the
    same code even when the loop found it through sys.path rather than an install."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (_ROOT, env.get("PYTHONPATH")) if p)
    return env


class Prestarted:
    """``python -m hofto_hw.runtime.prestart MODULE``: started now, arguments later
    (:meth:`send`); ``fds``: it will be sent file descriptors (a socket pair is made for
    them). Started at normal priority by whoever calls this before the real-time set-up."""

    def __init__(self, module: str, *, fds: bool = False) -> None:
        self.module = module
        self.sent = False
        self._ours: socket.socket | None = None
        argv = [sys.executable, "-m", "hofto_hw.runtime.prestart", module]
        theirs = None
        if fds:
            self._ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
            argv.append(str(theirs.fileno()))
        try:
            self.proc = subprocess.Popen(
                argv,
                stdin=subprocess.PIPE,
                close_fds=True,
                pass_fds=() if theirs is None else (theirs.fileno(),),
                env=child_env(),
            )
        except BaseException:
            if self._ours is not None:
                self._ours.close()
            raise
        finally:
            if theirs is not None:
                theirs.close()

    @property
    def pid(self) -> int:
        return self.proc.pid

    def send(self, args: Any, fds: list[int] | tuple[int, ...] = ()) -> None:
        """Hand the child its arguments (pickled) and ``fds`` (duplicated into it; ours stay
        open). A child that died already is left for its owner's health check to report."""
        if self.sent:
            raise RuntimeError(f"{self.module}: arguments sent already")
        self.sent = True
        if fds and self._ours is None:
            raise ValueError(f"{self.module}: started without a descriptor channel")
        assert self.proc.stdin is not None
        try:
            if self._ours is not None:
                socket.send_fds(self._ours, [b"\0"], list(fds))
            self.proc.stdin.write(pickle.dumps(args))
            self.proc.stdin.close()
        except (BrokenPipeError, ConnectionError):  # died at once
            pass
        finally:
            if self._ours is not None:
                self._ours.close()
                self._ours = None

    def poll(self) -> int | None:
        return self.proc.poll()

    def wait(self, timeout: float | None = None) -> int:
        return self.proc.wait(timeout)

    def kill(self) -> None:
        self.proc.kill()

    def abandon(self) -> None:
        """End a child that was never sent its arguments (it holds nothing: killed, reaped);
        nothing for one that was (its owner closes it)."""
        if self.sent:
            return
        self.sent = True
        if self._ours is not None:
            self._ours.close()
            self._ours = None
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait()
        if self.proc.stdin is not None:
            try:
                self.proc.stdin.close()
            except BrokenPipeError:
                pass


def _receive(fd_channel: int | None) -> tuple[Any, list[int]] | None:
    """The arguments and descriptors the parent sends; None when it sent nothing."""
    fds: list[int] = []
    if fd_channel is not None:
        with socket.socket(fileno=fd_channel) as chan:
            _msg, fds, _flags, _addr = socket.recv_fds(chan, 1, MAX_FDS)
    data = sys.stdin.buffer.read()
    sys.stdin.close()
    if not data:
        for fd in fds:
            os.close(fd)
        return None
    return pickle.loads(data), fds


def _main(argv: list[str]) -> int:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the loop's (Ctrl-C reaches the group)
    term = [0.0]
    signal.signal(signal.SIGTERM, lambda *_: term.__setitem__(0, time.monotonic()))
    import importlib

    module = importlib.import_module(argv[0])
    preload = getattr(module, "preload", None)
    if preload is not None:
        preload()
    got = _receive(int(argv[1]) if len(argv) > 1 else None)
    if got is None:
        return 0
    args, fds = got
    return int(module.child_main(args, fds, term) or 0)


if __name__ == "__main__":
    raise SystemExit(_main(sys.argv[1:]))
