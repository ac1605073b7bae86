"""A progress bar for long simulations (tqdm), silent when not interactive.

``simulate(...)`` shows one by default; ``with Progress(t_end, "mode ii") as cb:
simulate(..., progress=cb)`` drives one explicitly -- the callback takes
``(t_now, t_end)``. The bar appears only after ``delay`` seconds (runs shorter than
that print nothing) and only in an interactive session: stderr a terminal, or a
Jupyter notebook (``tqdm.auto`` then draws a widget); never in logs, pipes or tests,
unless ``enabled=True`` is forced.
"""
from __future__ import annotations

import sys
import time

__all__ = ["Progress"]


def interactive(file=None) -> bool:
    """True when ``file`` (default stderr) is a terminal or we run in a Jupyter kernel."""
    file = sys.stderr if file is None else file
    try:
        if file.isatty():
            return True
    except (AttributeError, ValueError):
        pass
    ip = sys.modules.get("IPython")
    if ip is not None:
        try:
            shell = ip.get_ipython()
        except Exception:  # noqa: BLE001 - no shell
            return False
        return shell is not None and type(shell).__name__ == "ZMQInteractiveShell"
    return False


class Progress:
    """Callable ``(t_now, t_end)`` driving a tqdm bar over simulated time."""

    def __init__(self, t_end: float, desc: str = "simulating", *, delay: float = 2.0,
                 enabled: bool | None = None, file=None):
        self.t_end = float(t_end)
        self.desc = desc
        self.delay = delay
        self.file = file if file is not None else sys.stderr
        if enabled is None:
            enabled = interactive(self.file)
        self.enabled = enabled
        self.bar = None
        self.calls = 0
        self.last_t = 0.0
        self._t0 = time.perf_counter()

    def __call__(self, t_now: float, t_end: float | None = None):
        self.calls += 1
        self.last_t = float(t_now)
        if not self.enabled:
            return
        if self.bar is None:
            if time.perf_counter() - self._t0 < self.delay:
                return
            from tqdm.auto import tqdm  # (tqdm only once a bar is shown: runs over ~2 s on a terminal)
            total = float(t_end) if t_end is not None else self.t_end
            self.bar = tqdm(total=total, desc=self.desc, unit="s", file=self.file, leave=False,
                            bar_format="{desc}: {percentage:3.0f}%|{bar}| t = {n:.3f}/{total:g} s "
                                       "[{elapsed}<{remaining}]")
        self.bar.n = min(float(t_now), self.bar.total)
        self.bar.refresh()

    def close(self):
        if self.bar is not None:
            self.bar.close()
            self.bar = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False
