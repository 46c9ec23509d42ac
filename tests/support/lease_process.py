"""The remote enabling input held by a process of its own, as a hand holds an enabling device:
``python -m support.lease_process SOCKET`` sends ``enable on`` at once (its reply is the first
JSON line on stdout), renews it every :data:`RENEW` seconds and, at a line on stdin or its
end, sends ``enable off`` (its reply is the last JSON line) and exits.

Why a process and not a thread of the test: the lease lapses 0.25 s after the last renewal
(``drag.enable_input.lease``, at most 0.25 s by the schema). A renewing thread shares the
test process's interpreter lock and its scheduling: on a loaded 2-core machine that process
was kept off the CPU long enough for the lease to lapse mid-push (``enabling_released``
during the scripted drag). Run as root, this process raises itself to SCHED_FIFO
:data:`PRIORITY` (below the emulators' 40 and the loop's 50) and sleeps to absolute
deadlines, so that the only scheduling left in the renewal path is the service's own.
"""

from __future__ import annotations

import json
import os
import select
import sys
import time

RENEW = 0.05  # [s] as the control-plane tests' lease holders
PRIORITY = 30


def main(argv: list[str]) -> int:
    from hofto_hw.client.connection import Connection

    (path,) = argv
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(PRIORITY))
    except (AttributeError, OSError):
        pass  # unprivileged: renews at normal priority
    conn = Connection(path)
    print(json.dumps(conn.call({"cmd": "enable", "on": True})), flush=True)
    late = 0.0  # the largest gap between two renewals beyond RENEW [s], reported at the end
    t = time.monotonic()
    while True:
        t += RENEW
        wait = max(0.0, t - time.monotonic())
        if select.select([sys.stdin], [], [], wait)[0]:
            break  # a line (or EOF): let go
        now = time.monotonic()
        late = max(late, now - t)
        t = max(t, now - RENEW)  # after a stall: the next renewal one period from now
        r = conn.call({"cmd": "enable", "on": True})
        if not r.get("ok"):
            print(json.dumps({**r, "renewal_refused": True}), flush=True)
    r = conn.call({"cmd": "enable", "on": False})
    conn.close()
    print(json.dumps({**r, "renew_late_max_s": round(late, 4)}), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
