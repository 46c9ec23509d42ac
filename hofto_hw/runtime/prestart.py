"""Helper processes of ``hofto-hw run`` started before their arguments exist.

The flight recorder's writer and the control plane run in processes of their own (nothing but
the loop runs Python in the loop's process). Each needs seconds to import numpy, numba,
pinocchio and our modules on a loaded machine, and its arguments (the config, the shared
memory's name, the listening socket) exist only once the loop's process has read the config.
:class:`Prestarted` starts one before its arguments exist; :meth:`Prestarted.send` hands them
over (pickled through a pipe; file descriptors over a socket pair, SCM_RIGHTS) and the child
calls ``MODULE.child_main(args, fds, term)`` (after ``MODULE.preload()``, if any, which
imports what the child needs beyond the loop's modules); :meth:`Prestarted.abandon` ends one
that will never get them (a refused config, a stop during the start-up): it holds nothing.

- ``fork=True`` (``hofto-hw run``): forked from the loop's process once it has imported its
  modules, before its progress thread and its real-time set-up. The child has the imports
  without doing them: on the shared 2-core machine every process's imports compete for the
  same CPUs, so helpers importing in parallel with the loop (``fork=False``) start no sooner.
  The parent freezes its heap out of the collector's sight first (``gc.freeze``: no
  collection in a child writes to every inherited object), and its mlockall afterwards
  copies the shared pages at once, not in the loop. This is how the control plane already
  forks its planner.
- ``fork=False``: ``python -m hofto_hw.runtime.prestart MODULE``, a fresh interpreter
  (FlightRecorder and ControlPlaneProcess used on their own: tests, tools).

In the child, from its first line: SIGINT is ignored (the loop's, e.g. Ctrl-C to the process
group) and SIGTERM only noted (``term[0]``, the monotonic time; each child's own grace period
counts from it): the loop's process decides when its helpers end. An empty pipe (the parent
gave up or died before sending) ends the child silently with exit 0. Its kernel name
(/proc/PID/comm, ``ps -o comm``) is ``hofto-hw-writer`` or ``hofto-hw-ctrl``.

A further helper is one more ``Prestarted("package.module", fork=True)`` in
:class:`hofto_hw.runtime.startup.Helpers` and a ``child_main(args, fds, term)`` in its module.
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
#: our ends of the pipes and channels of the helpers not yet sent their arguments: a child
#: forked later closes its copies (else a helper abandoned would never see its EOF)
_PARENT_ENDS: set[int] = set()


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

    def __init__(self, module: str, *, fds: bool = False, fork: bool = False) -> None:
        self.module = module
        self.sent = False
        self._ours: socket.socket | None = None
        theirs = None
        if fds:
            self._ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            if fork:
                self.proc: Any = _Forked(module, theirs, self._ours)
                self._stdin = self.proc.stdin
            else:
                argv = [sys.executable, "-m", "hofto_hw.runtime.prestart", module]
                if theirs is not None:
                    argv.append(str(theirs.fileno()))
                self.proc = subprocess.Popen(
                    argv,
                    stdin=subprocess.PIPE,
                    close_fds=True,
                    pass_fds=() if theirs is None else (theirs.fileno(),),
                    env=child_env(),
                )
                self._stdin = self.proc.stdin
        except BaseException:
            if self._ours is not None:
                self._ours.close()
            raise
        finally:
            if theirs is not None:
                theirs.close()
        if self._ours is not None:
            _PARENT_ENDS.add(self._ours.fileno())
        _PARENT_ENDS.add(self._stdin.fileno())

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
        try:
            if self._ours is not None:
                socket.send_fds(self._ours, [b"\0"], list(fds))
            self._stdin.write(pickle.dumps(args))
        except (BrokenPipeError, ConnectionError):  # died at once
            pass
        finally:
            self._close_ends()

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
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait()
        self._close_ends()

    def _close_ends(self) -> None:
        """Our ends of the child's stdin and descriptor channel (EOF for the child)."""
        _PARENT_ENDS.discard(self._stdin.fileno())
        try:
            self._stdin.close()
        except BrokenPipeError:
            pass
        if self._ours is not None:
            _PARENT_ENDS.discard(self._ours.fileno())
            self._ours.close()
            self._ours = None


class _Forked:
    """A child forked from this process (multiprocessing's fork start method), as much of
    subprocess.Popen's interface as :class:`Prestarted`'s owners use. Forked where the
    caller has imported its modules and runs one thread (no lock another thread holds is
    copied), before any real-time set-up: the child gets the imports for free; the
    parent's later mlockall breaks the copy-on-write sharing at once, not in the loop."""

    def __init__(
        self, module: str, theirs: socket.socket | None, ours: socket.socket | None
    ) -> None:
        import gc
        import multiprocessing

        # what is imported by now lives until exit: out of the collector's sight, so that a
        # collection in the child does not write to every inherited object (each page
        # copied, seconds on a loaded machine) and the parent's later ones skip it too
        gc.freeze()
        sys.stdout.flush()  # nothing buffered is written twice
        sys.stderr.flush()
        r, w = os.pipe()
        self.stdin = os.fdopen(w, "wb")
        channel = None if theirs is None else theirs.fileno()
        # our ends (this child's and the other helpers'): a child holding one would wait for
        # ever after its parent died, its EOF never coming
        close = sorted(_PARENT_ENDS | {w} | (set() if ours is None else {ours.fileno()}))
        self._p = multiprocessing.get_context("fork").Process(
            target=_forked_main,
            args=(module, r, channel, close),
            name=process_name(module),
            daemon=False,  # the control plane forks its planner (no child of a daemon)
        )
        try:
            self._p.start()
        except BaseException:
            self.stdin.close()
            raise
        finally:
            os.close(r)

    @property
    def pid(self) -> int:
        return int(self._p.pid or 0)

    def poll(self) -> int | None:
        return self._p.exitcode

    def wait(self, timeout: float | None = None) -> int:
        self._p.join(timeout)
        if self._p.exitcode is None:
            raise subprocess.TimeoutExpired(self._p.name, timeout or 0.0)
        return self._p.exitcode

    def kill(self) -> None:
        self._p.kill()


def _forked_main(module: str, stdin_fd: int, channel: int | None, close: list[int]) -> None:
    """The forked child: signals as :func:`_main`'s, the parent's other ends closed, then the
    module's preload, arguments and ``child_main``; exits with its code."""
    term = _child_signals()
    _set_name(process_name(module))
    for fd in close:
        try:
            os.close(fd)
        except OSError:
            pass
    sys.exit(_serve(module, channel, os.fdopen(stdin_fd, "rb"), term))


def _receive(fd_channel: int | None, stdin: Any) -> tuple[Any, list[int]] | None:
    """The arguments and descriptors the parent sends; None when it sent nothing."""
    fds: list[int] = []
    if fd_channel is not None:
        with socket.socket(fileno=fd_channel) as chan:
            _msg, fds, _flags, _addr = socket.recv_fds(chan, 1, MAX_FDS)
    data = stdin.read()
    stdin.close()
    if not data:
        for fd in fds:
            os.close(fd)
        return None
    return pickle.loads(data), fds


def process_name(module: str) -> str:
    """The helper's name in /proc/PID/comm (ps -o comm, top): ``hofto-hw-writer`` for
    hofto_hw.recording.writer_process, ``hofto-hw-ctrl`` for the control plane; a forked
    child's command line is its parent's."""
    return {"writer_process": "hofto-hw-writer", "process": "hofto-hw-ctrl"}.get(
        module.rsplit(".", 1)[-1], "hofto-hw-helper"
    )


def _set_name(name: str) -> None:
    """prctl(PR_SET_NAME): the kernel's name of this process (15 bytes: the names above
    fit); best effort."""
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(15, name.encode()[:15], 0, 0, 0)  # PR_SET_NAME
    except (OSError, AttributeError):
        pass


def _child_signals() -> list[float]:
    """SIGINT ignored (the loop's: Ctrl-C reaches the process group), SIGTERM noted in the
    returned ``term[0]`` (monotonic time)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    term = [0.0]
    signal.signal(signal.SIGTERM, lambda *_: term.__setitem__(0, time.monotonic()))
    return term


def _serve(module_name: str, channel: int | None, stdin: Any, term: list[float]) -> int:
    """Import (and preload) the module, wait for the arguments, run its ``child_main``."""
    import importlib

    module = importlib.import_module(module_name)
    preload = getattr(module, "preload", None)
    if preload is not None:
        preload()
    got = _receive(channel, stdin)
    if got is None:
        return 0
    args, fds = got
    return int(module.child_main(args, fds, term) or 0)


def _main(argv: list[str]) -> int:
    term = _child_signals()
    _set_name(process_name(argv[0]))
    return _serve(argv[0], int(argv[1]) if len(argv) > 1 else None, sys.stdin.buffer, term)


if __name__ == "__main__":
    raise SystemExit(_main(sys.argv[1:]))
