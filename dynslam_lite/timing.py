"""Per-stage wall-clock timing of a frame (the benchmarks' ms/frame per stage)."""
from __future__ import annotations

import time
from collections import defaultdict
from contextlib import contextmanager


class StageTimer:
    """Accumulates wall-clock milliseconds per named stage for the current frame."""

    def __init__(self):
        self.frame: dict[str, float] = defaultdict(float)

    @contextmanager
    def stage(self, name: str):
        t = time.perf_counter()
        try:
            yield
        finally:
            self.frame[name] += (time.perf_counter() - t) * 1000.0

    def add(self, name: str, ms: float) -> None:
        """Charge ``ms`` to a stage: work of this frame done earlier and kept (:meth:`Frame.derive`)."""
        self.frame[name] += ms
