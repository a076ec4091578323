"""Progress of the frames described inside one cell, reported to whoever shows it.

Describing happens deep in the evaluation (`evaluation.cell.describe`, the descriptor cache's
chunks) while the bar that shows it belongs to the runner. Rather than thread a callback through
every signature between them, the runner installs a `FrameProgress` for the duration of a cell
(`reporting`) and the code that describes calls `expect` and `advance`; with none installed they
do nothing, so library use, workers and tests are unaffected. A context variable, not a global:
a thread that did not install one reports to nobody.

`interactive` says whether a stream is a terminal: bars that redraw in place (carriage returns)
only make sense there; a log file or CI gets plain lines instead (`safl_bench.run.runner`).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from typing import Any, Protocol


class FrameProgress(Protocol):
    """What shows frames being described: `expect` adds frames to the total, `advance` counts
    frames done (described now or read from a cache)."""

    def expect(self, n: int) -> None: ...

    def advance(self, n: int) -> None: ...


_current: ContextVar[FrameProgress | None] = ContextVar("safl_frame_progress", default=None)


@contextmanager
def reporting(progress: FrameProgress | None) -> Iterator[None]:
    """Send `expect` and `advance` to `progress` inside the block (None: to nobody)."""
    token = _current.set(progress)
    try:
        yield
    finally:
        _current.reset(token)


def expect(n: int) -> None:
    """`n` more frames are to be described in the current cell."""
    progress = _current.get()
    if progress is not None:
        progress.expect(n)


def advance(n: int) -> None:
    """`n` frames of the current cell are done."""
    progress = _current.get()
    if progress is not None:
        progress.advance(n)


#: The latest word on the step a `heartbeat` watches ("" when there is none), set by `report`.
_latest: list[str] = [""]


def report(text: str) -> None:
    """Say how far a long step has got (e.g. "maps L0: 6 of 20 chunks"); the running
    `heartbeat` adds it to its next line. Cheap, and harmless when no heartbeat runs."""
    _latest[0] = text


@contextmanager
def heartbeat(say: Callable[[str], None] | None, what: str, every_s: float = 30.0) -> Iterator[None]:
    """While the block runs, `say` "<what>: still working (N s)" every `every_s` seconds, so a
    log never falls silent through a long step that reports nothing itself (building views,
    generating the synthetic data); None: nothing is said. A daemon thread, stopped on exit."""
    if say is None:
        yield
        return
    stop = threading.Event()
    start = time.monotonic()
    _latest[0] = ""

    def beat() -> None:
        while not stop.wait(every_s):
            latest = f"; {_latest[0]}" if _latest[0] else ""
            say(f"  {what}: still working ({time.monotonic() - start:.0f} s{latest})")

    thread = threading.Thread(target=beat, name="safl-heartbeat", daemon=True)
    thread.start()
    try:
        yield
    finally:
        stop.set()
        thread.join()
        _latest[0] = ""


def interactive(stream: Any) -> bool:
    """Whether `stream` is a terminal (a closed or odd stream is not)."""
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError, OSError):
        return False
