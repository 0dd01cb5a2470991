"""A dependency-free progress bar for long CLI work (stderr; one redrawn line on a terminal,
a few plain lines in logs)."""

from __future__ import annotations

import sys
import time
from typing import Iterable, Iterator, TextIO, TypeVar

T = TypeVar("T")


class Progress:
    """Progress of ``total`` steps. Use as a context manager and call :meth:`advance`."""

    def __init__(self, total: int, desc: str, stream: TextIO | None = None, enabled: bool = True) -> None:
        self.total, self.desc, self.done = max(int(total), 1), desc, 0
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = enabled
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.start = time.perf_counter()
        self._last_logged = -1

    def advance(self, n: int = 1, note: str = "") -> None:
        self.done = min(self.done + n, self.total)
        self._draw(note)

    def _draw(self, note: str = "") -> None:
        if not self.enabled:
            return
        frac = self.done / self.total
        elapsed = time.perf_counter() - self.start
        bar = "#" * int(24 * frac) + "-" * (24 - int(24 * frac))
        line = f"{self.desc} [{bar}] {self.done}/{self.total} {elapsed:6.1f}s {note}"
        if self.tty:
            self.stream.write("\r" + line[:150].ljust(150))
        else:  # logs: one line per quarter
            quarter = int(4 * frac)
            if quarter == self._last_logged:
                return
            self._last_logged = quarter
            self.stream.write(line + "\n")
        self.stream.flush()

    def __enter__(self) -> "Progress":
        self._draw()
        return self

    def __exit__(self, *exc: object) -> None:
        if self.enabled and self.tty:
            self.stream.write("\n")
            self.stream.flush()


def progress(items: Iterable[T], desc: str, total: int | None = None, enabled: bool = True) -> Iterator[T]:
    """Iterate over ``items`` with a progress bar."""
    items = list(items) if total is None else items
    with Progress(total if total is not None else len(items), desc, enabled=enabled) as bar:  # type: ignore[arg-type]
        for item in items:
            yield item
            bar.advance()
