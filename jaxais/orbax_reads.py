"""A quiet end to an orbax restore that failed (the seed and GA checkpoint readers use it).

orbax reads a checkpoint's arrays concurrently, on an event loop of its own, and closes that loop
as soon as one read fails. The other reads end a moment later, and Python then reports them in
two ways, both after the caller has already said what is wrong (a script's one-line error about
a corrupt checkpoint):

- tensorstore's completion callbacks find the loop closed: each is an unraisable
  ``RuntimeError('Event loop is closed')``, printed with a traceback;
- the failed reads' futures are garbage-collected with their errors unread: asyncio logs
  "Future (or Task) exception was never retrieved" with tensorstore's error.

:func:`forget_abandoned_reads` drops exactly those reports and lets everything else through.
"""

from __future__ import annotations

import logging
import sys
from typing import Any

_LOOP_CLOSED = "Event loop is closed"
_NEVER_RETRIEVED = ("Future exception was never retrieved", "Task exception was never retrieved")
_READ_ERRORS = ('"zarr" driver', "OCDBT database")
"""Words of tensorstore's errors for a checkpoint's arrays (zarr arrays in an OCDBT store)."""


def _is_late_callback(unraisable: Any) -> bool:
    """Whether an unraisable exception is the callback of a read whose loop has closed."""
    return unraisable.exc_type is RuntimeError and str(unraisable.exc_value) == _LOOP_CLOSED


class _UnreadReadErrors(logging.Filter):
    """Drops asyncio's reports of checkpoint-read errors that nobody retrieved."""

    def filter(self, record: logging.LogRecord) -> bool:
        error = record.exc_info[1] if record.exc_info else None
        unread = str(record.msg).startswith(_NEVER_RETRIEVED)
        return not (unread and isinstance(error, ValueError) and _mentions_a_read(error))


def _mentions_a_read(error: BaseException) -> bool:
    return any(words in str(error) for words in _READ_ERRORS)


def forget_abandoned_reads() -> None:
    """Drop the abandoned reads' reports from now on; let every other report through.

    Call it before a restore (after a failure the first late report can come at once).
    Installed once per process: over whatever ``sys.unraisablehook`` was there before, and as a
    filter of the ``asyncio`` logger.
    """
    if not getattr(sys.unraisablehook, "_drops_abandoned_reads", False):
        previous = sys.unraisablehook

        def hook(unraisable: Any) -> None:
            if not _is_late_callback(unraisable):
                previous(unraisable)

        hook._drops_abandoned_reads = True  # type: ignore[attr-defined]
        sys.unraisablehook = hook
    log = logging.getLogger("asyncio")
    if not any(isinstance(f, _UnreadReadErrors) for f in log.filters):
        log.addFilter(_UnreadReadErrors())
