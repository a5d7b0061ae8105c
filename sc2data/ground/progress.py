"""Progress bars: tqdm's live bar on a terminal, a plain line now and then in a log file."""

from __future__ import annotations

import sys
from typing import Any, Protocol, TextIO


class Bar(Protocol):
    """What sc2data's stages use of a progress bar (a tqdm bar; tqdm itself loads lazily)."""

    n: float
    total: float | None

    def update(self, n: float = 1) -> bool | None: ...

    def refresh(self) -> None: ...

    def set_postfix(self, **values: Any) -> None: ...

    def __enter__(self) -> Any: ...

    def __exit__(self, *exc: object) -> None: ...

LOG_EVERY_S = 60.0
"""With stderr redirected to a file, a progress line every this many seconds, and none at all
for work that ends sooner (so short commands and one-line errors stay clean)."""


class _Lines:
    """A stream for tqdm that writes each redraw as a whole line instead of a carriage return."""

    def __init__(self, stream: TextIO) -> None:
        self.stream = stream

    def write(self, text: str) -> None:
        text = text.replace("\r", "").strip()
        if text:
            self.stream.write(text + "\n")

    def flush(self) -> None:
        self.stream.flush()


def bar(total: int, *, desc: str, unit: str, show: bool | None, leave: bool = True) -> Bar:
    """A tqdm progress bar over ``total`` units.

    ``show``: True, a live bar; False, none; None, a live bar when stderr is a terminal and, when
    it is a file (``sc2data build … 2> log``), one line every :data:`LOG_EVERY_S` seconds once
    the work has lasted that long. ``leave``: keep the finished live bar on the terminal.
    """
    from tqdm import tqdm

    if show is None and not sys.stderr.isatty():
        return tqdm(total=total, desc=desc, unit=unit, unit_scale=True, ascii=True, ncols=100,
                    file=_Lines(sys.stderr), mininterval=LOG_EVERY_S, maxinterval=LOG_EVERY_S,
                    delay=LOG_EVERY_S)
    return tqdm(total=total, desc=desc, unit=unit, unit_scale=True, dynamic_ncols=True,
                smoothing=0.1, disable=show is False, leave=leave)
