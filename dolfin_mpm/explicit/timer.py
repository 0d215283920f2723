"""Stage timers that do not overlap: each lap ends one stage and starts the next."""

import time
from collections import defaultdict

__all__ = ["Timer"]


class Timer:
    """Wall-clock seconds per stage, accumulated over steps, adding up to the steps' time.

    A step calls :meth:`start` once, then :meth:`lap` after each stage: a lap charges the time
    since the previous one to its stage, so no instant is counted twice or left out and the
    stages sum to the step (``total``).
    """

    def __init__(self):
        self.seconds: dict[str, float] = defaultdict(float)
        self._last = 0.0

    def start(self) -> None:
        self._last = time.perf_counter()

    def lap(self, stage: str) -> None:
        now = time.perf_counter()
        self.seconds[stage] += now - self._last
        self._last = now

    @property
    def total(self) -> float:
        """Seconds of all stages [s]."""
        return sum(self.seconds.values())
