"""A failed orbax restore ends with the caller's error alone (``jaxais.orbax_reads``)."""

from __future__ import annotations

import logging
import sys
import types

from jaxais import orbax_reads


def _event(exc: BaseException) -> types.SimpleNamespace:
    """What Python hands ``sys.unraisablehook``."""
    return types.SimpleNamespace(
        exc_type=type(exc), exc_value=exc, exc_traceback=None, err_msg=None, object=None
    )


def test_the_hook_drops_late_callbacks_only_and_installs_once(monkeypatch):
    seen = []
    monkeypatch.setattr(sys, "unraisablehook", seen.append)
    orbax_reads.forget_abandoned_reads()
    hook = sys.unraisablehook
    orbax_reads.forget_abandoned_reads()
    assert sys.unraisablehook is hook  # not wrapped twice
    late = _event(RuntimeError("Event loop is closed"))
    others = [_event(RuntimeError("another error")), _event(ValueError("Event loop is closed"))]
    for event in [late, *others]:
        sys.unraisablehook(event)
    assert seen == others  # everything else reaches the hook that was there before


def _record(msg: str, error: BaseException | None) -> logging.LogRecord:
    exc_info = (type(error), error, None) if error is not None else None
    return logging.LogRecord("asyncio", logging.ERROR, __file__, 1, msg, None, exc_info)


def test_the_asyncio_filter_drops_unread_checkpoint_read_errors_only(monkeypatch):
    log = logging.getLogger("asyncio")
    monkeypatch.setattr(log, "filters", [])
    orbax_reads.forget_abandoned_reads()
    orbax_reads.forget_abandoned_reads()
    assert len(log.filters) == 1  # installed once
    read = ValueError('NOT_FOUND: Error opening "zarr" driver: Metadata at "L/.zarray" ...')
    dropped = [
        _record("Future exception was never retrieved\nfuture: <Future ...>", read),
        _record("Task exception was never retrieved\nfuture: <Task ...>", read),
    ]
    kept = [
        _record("Future exception was never retrieved", ValueError("a user's own error")),
        _record("Future exception was never retrieved", RuntimeError('"zarr" driver')),
        _record("Exception in callback", read),
        _record("Unclosed event loop", None),
    ]
    assert [log.filter(r) for r in dropped] == [False, False]
    assert all(log.filter(r) for r in kept)
