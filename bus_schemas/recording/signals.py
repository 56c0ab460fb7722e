"""Finishing a recording on SIGTERM/SIGINT (a mixin of the
:class:`~bus_schemas.recording.recorder.Recorder`): the handler writes what was queued,
records a ``signal`` metadata entry and finishes the file, at once or, when a write is in
progress, at its end (the MCAP writer must be in a consistent state: writes run inside
:meth:`SignalFinish._critical` or set ``_busy`` themselves); then the program exits
(``exit=True``) or the recorder drops later writes for a caller that polls."""

from __future__ import annotations

import contextlib
import signal
from collections.abc import Callable, Iterable, Iterator, Mapping
from pathlib import Path
from types import FrameType
from typing import TYPE_CHECKING, Any


class SignalFinish:
    """Signal handling of the recorder (it finishes the file through the recorder's
    ``write_deferred``, ``add_metadata`` and ``finish``)."""

    finished: bool
    message_count: int

    if TYPE_CHECKING:
        def write_deferred(self, stop: Callable[[], bool] | None = None) -> int: ...

        def add_metadata(self, name: str, data: Mapping[str, Any]) -> None: ...

        def finish(self) -> Path: ...

    def __init__(self) -> None:
        self.interrupted: int | None = None  # the signal that finished the file
        self._busy = False  # a write is in progress: a signal waits for its end
        self._pending: int | None = None  # the signal that came during a write
        self._exit_on_signal = True
        self._old_handlers: dict[int, Any] = {}

    def install_signal_handlers(self, signals: Iterable[int] = (signal.SIGTERM,
                                                                signal.SIGINT),
                                *, exit: bool = True) -> None:
        """On any of ``signals``: record a ``signal`` metadata entry and finish the file,
        then (``exit=True``) raise ``SystemExit(128 + signum)`` (``KeyboardInterrupt`` for
        SIGINT) so the program unwinds; with ``exit=False`` set :attr:`interrupted` and
        drop further writes, for a caller that polls it. Main thread only."""
        self._exit_on_signal = exit
        for s in signals:
            self._old_handlers[s] = signal.signal(s, self._on_signal)

    def restore_signal_handlers(self) -> None:
        """Put back the handlers replaced by :meth:`install_signal_handlers`."""
        for s, h in self._old_handlers.items():
            signal.signal(s, h)
        self._old_handlers.clear()

    @contextlib.contextmanager
    def _critical(self) -> Iterator[None]:
        """Defer signal handling until the MCAP writer is in a consistent state."""
        outer = self._busy
        self._busy = True
        try:
            yield
        finally:
            self._busy = outer
        if not outer and self._pending is not None:
            self._handle_pending()

    def _on_signal(self, signum: int, frame: FrameType | None) -> None:
        self._pending = signum
        if not self._busy:
            self._handle_pending()

    def _handle_pending(self) -> None:
        signum, self._pending = self._pending, None
        if signum is None:
            return
        if not self.finished:
            self.write_deferred()  # what was queued before the signal is part of the run
            self.interrupted = signum
            self.add_metadata("signal", {"signal": signal.Signals(signum).name,
                                         "messages": str(self.message_count)})
            self.finish()
        if self._exit_on_signal:
            if signum == signal.SIGINT:
                raise KeyboardInterrupt
            raise SystemExit(128 + signum)
