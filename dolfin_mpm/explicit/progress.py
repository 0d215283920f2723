"""Progress of a run on rank 0: a bar on a terminal, plain log lines elsewhere (CI, files)."""

import shutil
import sys
import time

__all__ = ["Progress"]


def _clock(seconds: float) -> str:
    if seconds != seconds or seconds == float("inf"):
        return "--:--:--"
    s = round(seconds)
    return f"{s // 3600:d}:{s // 60 % 60:02d}:{s % 60:02d}"


class Progress:
    """Shows simulated time, steps/s, ETA, particle count and (if given) discharged mass.

    Args:
        t_start, t_end: the span of the run [s].
        dt: the time step [s] (for the ETA).
        stream: where to write; a terminal gets one line redrawn in place (a bar), anything
            else a line every ``log_every`` seconds.
        enabled: ``False`` on ranks other than 0, or to stay silent.
        mass_unit: unit of the discharged mass (``kg/m`` in 2D).
        log_every: seconds between log lines when ``stream`` is not a terminal.

    """

    def __init__(self, t_start, t_end, dt, stream=None, enabled=True, mass_unit="kg", log_every=10.0):
        self.t_start, self.t_end, self.dt = t_start, t_end, dt
        self.stream = sys.stdout if stream is None else stream
        self.enabled, self.mass_unit = enabled, mass_unit
        self.tty = enabled and hasattr(self.stream, "isatty") and self.stream.isatty()
        self.every = 0.2 if self.tty else log_every
        self.t0 = self.last = time.perf_counter()
        self.steps = -1  # the rate counts from the end of the first step (start-up left out)
        self._open = False  # a bar is drawn and its line not ended

    def due(self) -> bool:
        """Count a step; true when the display should be refreshed (never on silent ranks)."""
        if self.steps < 0:
            self.t0 = time.perf_counter()
        self.steps += 1
        return self.enabled and time.perf_counter() - self.last >= self.every

    def show(
        self, t: float, particles: int, discharged: float | None = None, imbalance: float | None = None,
        final: bool = False,
    ) -> None:  # fmt: skip
        """Redraw the bar or write a log line for simulated time ``t`` [s].

        ``discharged`` (the mass through the sinks) and ``imbalance`` (the largest rank's
        particles over the mean, under MPI) are shown when given.
        """
        if not self.enabled:
            return
        now = time.perf_counter()
        self.last = now
        rate = max(self.steps, 0) / max(now - self.t0, 1e-9)
        eta = max(self.t_end - t, 0.0) / self.dt / rate if rate > 0 else float("inf")
        span = max(self.t_end - self.t_start, 1e-300)
        fraction = min(max((t - self.t_start) / span, 0.0), 1.0)
        text = f"t = {t:.4e} s  {rate:7.1f} steps/s  ETA {_clock(eta)}  particles {particles}"
        if discharged is not None:
            text += f"  discharged {discharged:.4g} {self.mass_unit}"
        if imbalance is not None:
            text += f"  imbalance {imbalance:.2f}"
        if self.tty:  # one line, cleared to its end; on a narrow terminal without the bar, cut
            bar = "#" * round(20 * fraction) + "-" * (20 - round(20 * fraction))
            line = f"[{bar}] {100 * fraction:5.1f}%  {text}"
            width = shutil.get_terminal_size(fallback=(0, 0)).columns
            if 0 < width <= len(line):
                line = f"{100 * fraction:5.1f}%  {text}"[: width - 1]
            self.stream.write(f"\r{line}\x1b[K" + ("\n" if final else ""))
            self._open = not final
        else:
            self.stream.write(f"{100 * fraction:5.1f}%  {text}\n")
        self.stream.flush()

    def end_line(self) -> None:
        """End the bar's line, so that what is printed next starts on its own."""
        if self._open:
            self.stream.write("\n")
            self.stream.flush()
            self._open = False
