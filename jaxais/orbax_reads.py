"""A quiet end to an orbax restore that failed (the seed and GA checkpoint readers use it).

orbax reads arrays concurrently on an event loop it closes at the first failure; the other reads
then end with reports printed after the caller's one-line error: unraisable ``RuntimeError('Event
loop is closed')`` tracebacks and asyncio's "exception was never retrieved" logs.
:func:`forget_abandoned_reads` drops exactly those and lets everything else through.
"""

from __future__ import annotations

import logging
import sys
from typing import Any

_LOOP_CLOSED = "Event loop is closed"
_NEVER_RETRIEVED = ("Future exception was never retrieved", "Task exception was never retrieved")
_READ_ERRORS = ('"zarr" driver', "OCDBT database")  # tensorstore's words for a checkpoint read


class _UnreadReadErrors(logging.Filter):
    """Drops asyncio's reports of checkpoint-read errors that nobody retrieved."""

    def filter(self, record: logging.LogRecord) -> bool:
        error = record.exc_info[1] if record.exc_info else None
        unread = str(record.msg).startswith(_NEVER_RETRIEVED)
        of_a_read = isinstance(error, ValueError) and any(w in str(error) for w in _READ_ERRORS)
        return not (unread and of_a_read)


def forget_abandoned_reads() -> None:
    """Drop the abandoned reads' reports from now on (call before a restore); installed once
    per process, over the previous ``sys.unraisablehook`` and as an ``asyncio`` log filter."""
    if not getattr(sys.unraisablehook, "_drops_abandoned_reads", False):
        previous = sys.unraisablehook

        def hook(unraisable: Any) -> None:
            # The callback of a read whose loop has closed is dropped.
            late = unraisable.exc_type is RuntimeError and str(unraisable.exc_value) == _LOOP_CLOSED
            if not late:
                previous(unraisable)

        hook._drops_abandoned_reads = True  # type: ignore[attr-defined]
        sys.unraisablehook = hook
    log = logging.getLogger("asyncio")
    if not any(isinstance(f, _UnreadReadErrors) for f in log.filters):
        log.addFilter(_UnreadReadErrors())
