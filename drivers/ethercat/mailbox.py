"""A slave's CoE mailbox brought back in step after an SDO transfer that got no valid answer.

SOEM's ``ecx_SDOread`` empties the slave's read mailbox once, without waiting, sends the
request and takes the first SDO response whose *index* matches; it does not compare the
subindex, and it takes an abort whatever object the abort names. A transfer that timed out
(or whose answer was refused as an unexpected frame) may still be answered later: when that
answer comes after the next transfer's quick emptying, the next read of the same object
takes it as its own (0x1018:02 read as 0x1018:01's value: a wrong identity, a wrong PDO
entry count, a wrong scaling) and any other transfer takes a late abort.

A slave answers its mailbox requests in order, so a clean answer to a request sent after
the failed one proves that every answer before it has been read out. :func:`resync` sends
such requests: reads of subindex 0 of objects every CoE drive has, each attempt a different
index and none the failed transfer's, so no late answer can pass for the one awaited (SOEM
would refuse it as an unexpected frame, which only means the next attempt is needed).
"""

from __future__ import annotations

from collections.abc import Callable

#: objects every CiA-402 CoE slave has (ETG.1000.6: device type, identity, SM communication
#: types; CiA 402: axis 0's statusword), read at subindex 0 by :func:`resync`
FENCE_OBJECTS = (0x1000, 0x1018, 0x1C00, 0x6041)


def resync(
    read: Callable[[int, int], bytes],
    errors: tuple[type[BaseException], ...],
    failed_index: int,
) -> int | None:
    """Read fence objects with ``read(index, subindex)`` (the slave's SDO upload) until one
    answers cleanly; returns its index, or None when none did (the mailbox is still out of
    step). ``errors``: what ``read`` raises for no answer, an unexpected frame or an abort
    (an abort here may be a late one of the failed transfer). ``failed_index``: the object of
    the transfer that failed, never used as a fence."""
    for index in FENCE_OBJECTS:
        if index == failed_index:
            continue
        try:
            read(index, 0)
        except errors:
            continue  # a late answer taken and refused, or this read's own answer late
        return index
    return None


def fence_names(failed_index: int) -> str:
    """The fence objects :func:`resync` reads after a failure on ``failed_index``, in words."""
    return ", ".join(f"0x{i:04X}:00" for i in FENCE_OBJECTS if i != failed_index)
