"""Say so on the terminal while Numba compiles: the first run of a command after installing (or
upgrading) granchain compiles the kernels it uses, 10-20 s on a laptop for one integrator, and a
newcomer who sees nothing for that long cannot tell a compilation from a hang.

Numba announces a compilation only when its on-disk cache has no machine code for the function
(the ``numba:compile`` event, which a cache load does not trigger), so nothing is printed once the
kernels are cached."""

from __future__ import annotations

import sys
import time
from contextlib import contextmanager

from numba.core import event


class _Notice(event.Listener):
    """A listener of Numba's ``numba:compile`` events: the first compilation prints one line, and
    :meth:`summary` gives the time spent compiling. Compilations nest (a kernel compiles the helpers
    it calls); only the outermost are timed."""

    def __init__(self, stream):
        self.stream = stream
        self.depth = 0
        self.started = None
        self.seconds = 0.0
        self.count = 0

    def on_start(self, event):
        if self.depth == 0:
            if self.count == 0:
                print("granchain: compiling the kernels this command uses (first run after installing or upgrading; "
                      "cached on disk, later runs skip this) ...", file=self.stream, flush=True)
            self.started = time.perf_counter()
            self.count += 1
        self.depth += 1

    def on_end(self, event):
        self.depth -= 1
        if self.depth == 0 and self.started is not None:
            self.seconds += time.perf_counter() - self.started
            self.started = None

    def summary(self) -> str | None:
        if self.count == 0:
            return None
        return f"granchain: {self.seconds:.1f} s of this run went into compiling (now cached)"


@contextmanager
def compile_notice(stream=None, quiet: bool = False):
    """Within the block, announce Numba's first compilation on ``stream`` (default stderr) and, at the
    end, the time compilation took; nothing with ``quiet`` or when every kernel came from the cache."""
    if quiet:
        yield None
        return
    notice = _Notice(sys.stderr if stream is None else stream)
    with event.install_listener("numba:compile", notice):
        try:
            yield notice
        finally:
            text = notice.summary()
            if text is not None:
                print(text, file=notice.stream, flush=True)
