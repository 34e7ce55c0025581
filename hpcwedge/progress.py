"""Progress on stderr: a tqdm bar on a terminal, periodic plain lines in a batch log."""
from __future__ import annotations

import sys
import time


class Progress:
    """Callable taking the engines' progress dicts ({"done", "total", "rays", "elapsed"}).

    On a terminal: a tqdm bar per stage. Otherwise (batch logs): one line every
    `every` seconds and one at the end of each stage. quiet=True: nothing.
    """

    def __init__(self, quiet: bool = False, every: float = 10.0, stream=None):
        self.stream = stream or sys.stderr
        self.quiet = quiet
        self.every = every
        self.tty = hasattr(self.stream, "isatty") and self.stream.isatty()
        self.label = ""
        self._bar = None
        self._last = 0.0

    def stage(self, label: str) -> "Progress":
        self.close()
        self.label = label
        self._last = time.monotonic()
        return self

    def __call__(self, info: dict) -> None:
        if self.quiet:
            return
        done, total = info.get("done", 0), info.get("total", 0)
        if self.tty:
            if self._bar is None:
                from tqdm import tqdm
                self._bar = tqdm(total=total, desc=self.label, unit="constraint",
                                 file=self.stream, leave=False)
            self._bar.n = done
            self._bar.set_postfix(rays=info.get("rays"), refresh=False)
            self._bar.refresh()
            return
        now = time.monotonic()
        if now - self._last >= self.every or done == total:
            self._last = now
            print(f"[hpcwedge] {self.label}: {done}/{total} constraints, "
                  f"{info.get('rays', 0)} live rays, {info.get('elapsed', 0.0):.1f} s",
                  file=self.stream, flush=True)

    def note(self, text: str) -> None:
        if not self.quiet:
            self.close()
            print(f"[hpcwedge] {text}", file=self.stream, flush=True)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()
            self._bar = None
