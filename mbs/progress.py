"""A progress bar for long simulations (tqdm), silent when not interactive.

``simulate(...)`` shows one by default; ``with Progress(t_end, "mode ii") as cb:
simulate(..., progress=cb)`` drives one explicitly -- the callback takes
``(t_now, t_end)``. The bar appears only after ``delay`` seconds (runs shorter than
that print nothing) and only in an interactive session: stderr a terminal, or a
Jupyter notebook (``tqdm.auto`` then draws a widget); never in logs, pipes or tests,
unless ``enabled=True`` is forced.

A bar that a command drives from its start (``python -m mbs simulate``, ``demo``)
also names what the command is doing (:meth:`Progress.phase`: "model", "compiling",
"solving", "sampling 64 trajectories", "figures") and counts its clock from ``start``
(the command's start, ``time.time()``), through the phases in which the solver calls
nothing: a thread redraws it twice a second (interactive sessions only).

:func:`compile_note` tells, before the first call of a kernel family, whether numba's
on-disk cache of its kernels is cold (a first run, or a run after the kernels' source
changed): then the first call compiles for tens of seconds.
"""
from __future__ import annotations

import sys
import threading
import time

__all__ = ["Progress", "interactive", "kernel_cache_warm", "cold_families", "compile_note", "KERNEL_FAMILIES"]

#: kernel families: the modules of their numba kernels (``@njit(cache=True)``) and about
#: how long they take to compile from a cold cache on a 2-core machine [s], rounded
#: from runs (docs/lab/code_notes.md)
KERNEL_FAMILIES = {
    "interval": (("verified.arith._kernels", "verified.series.taylor", "verified.arith.linalg"), 30),
    "Taylor-model": (("verified.series.taylor_model", "verified.steppers.tm_flow"), 45),
    "affine": (("verified.series.affine_taylor",), 30),
}


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


def kernel_cache_warm(module: str):
    """``(warm, total)``: how many of ``module``'s cached numba kernels have an entry in
    numba's on-disk cache that this process can load (an index file whose source stamp
    matches the module's source and whose entries were compiled for this CPU); None when
    that cannot be told (not importable, no cached kernels, numba internals changed).
    Reads numba's index files only (milliseconds); compiles nothing."""
    try:
        mod = sys.modules.get(module)
        if mod is None:  # (the kernel modules of KERNEL_FAMILIES; by name they are not imported here)
            from verified.arith import _kernels, linalg  # noqa: F401
            from verified.series import affine_taylor, taylor, taylor_model  # noqa: F401
            from verified.steppers import tm_flow  # noqa: F401
            mod = sys.modules.get(module)
        if mod is None:
            return None
        warm = total = 0
        for obj in list(vars(mod).values()):
            cache = getattr(obj, "_cache", None)
            index = getattr(cache, "_cache_file", None)
            if index is None or not hasattr(index, "_load_index"):
                continue  # not a dispatcher with an on-disk cache
            total += 1
            magic = obj.targetctx.codegen().magic_tuple()
            if any(len(k) > 1 and k[1] == magic for k in index._load_index()):
                warm += 1
        return (warm, total) if total else None
    except Exception:  # noqa: BLE001 - a heuristic: never break a run
        return None


def cold_families(families=("interval",), probe=None):
    """The kernel families of ``families`` (keys of :data:`KERNEL_FAMILIES`) whose
    kernels will compile on their first call here: fewer than half of their modules'
    cached kernels are in the cache (a family that a run uses compiles most of its
    kernels; one that some other run used is at least half warm). Returns a list of
    names, or None when the cache could not be read (then say nothing). ``probe``:
    ``module -> (warm, total) or None`` (default :func:`kernel_cache_warm`)."""
    probe = kernel_cache_warm if probe is None else probe
    cold = []
    for fam in families:
        warm = total = 0
        for module in KERNEL_FAMILIES[fam][0]:
            state = probe(module)
            if state is None:
                return None
            warm, total = warm + state[0], total + state[1]
        if 2 * warm < total:
            cold.append(fam)
    return cold


def compile_note(families=("interval",), what: str = "", probe=None) -> str:
    """One line to show before the first call of ``families``' kernels when their cache
    is cold (:func:`cold_families`), e.g. ``"compiling interval kernels (first run only,
    about 25 s) ..."``; "" when warm or unknown. ``what``: for what (" for the frame
    enclosures")."""
    cold = cold_families(families, probe)
    if not cold:
        return ""
    secs = sum(KERNEL_FAMILIES[f][1] for f in cold)
    names = cold[0] if len(cold) == 1 else ", ".join(cold[:-1]) + " and " + cold[-1]
    return f"compiling {names} kernels{what} (first run only, about {secs} s) ..."


class Progress:
    """Callable ``(t_now, t_end)`` driving a tqdm bar over simulated time.

    ``start``: the clock's origin (``time.time()``; default: now), e.g. the start of the
    command, so that the bar's elapsed time counts model building, compiling, sampling
    and figures too. :meth:`phase` names what runs now (shown in the bar's description
    after ``desc``)."""

    def __init__(self, t_end: float, desc: str = "simulating", *, delay: float = 2.0,
                 enabled: bool | None = None, file=None, start: float | None = None):
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
        self.offset = 0.0  # added to t_now (several runs on one bar, e.g. the demo's modes)
        self.phase_name = ""
        self._then = None  # the phase from the first step on (phase(..., then=...))
        self.start = time.time() if start is None else float(start)
        self._lock = threading.RLock()
        self._stop = threading.Event()
        self._thread = None

    # -- the bar
    def _description(self) -> str:
        return f"{self.desc}: {self.phase_name}" if self.phase_name else self.desc

    def _show(self):
        """Draw the bar once ``delay`` s have passed since ``start`` (lock held)."""
        if self.bar is not None or self._stop.is_set() or time.time() - self.start < self.delay:
            return  # (shown, closed, or too early)
        from tqdm.auto import tqdm  # (tqdm only once a bar is shown: runs over ~2 s on a terminal)
        self.bar = tqdm(total=self.t_end, desc=self._description(), unit="s",
                        file=self.file, leave=False, delay=1e-9,  # (drawn below, once its clock is set)
                        bar_format="{desc}: {percentage:3.0f}%|{bar}| t = {n:.3f}/{total:g} s "
                                   "[{elapsed}<{remaining}]")
        self.bar.start_t = self.start  # the clock counts from the command's start
        self.bar.n = min(self.last_t, self.bar.total)
        self.bar.refresh()

    def _tick(self):
        """Redraw twice a second (phases without solver steps: compiling, sampling, figures)."""
        while not self._stop.wait(0.5):
            with self._lock:
                if self._stop.is_set():
                    return
                self._show()
                if self.bar is not None:
                    self.bar.refresh()

    def _start_thread(self):
        if self.enabled and self._thread is None and not self._stop.is_set():
            self._thread = threading.Thread(target=self._tick, name="mbs-progress", daemon=True)
            self._thread.start()

    def __call__(self, t_now: float, t_end: float | None = None):
        self.calls += 1
        self.last_t = self.offset + float(t_now)
        if not self.enabled:
            return
        with self._lock:
            if self._then is not None:  # the first step: compiled, the model built
                self.phase_name, self._then = self._then, None
                if self.bar is not None:
                    self.bar.set_description_str(self._description(), refresh=False)
            self._show()
            if self.bar is None:
                return
            n = min(self.last_t, self.bar.total)
            if n >= self.bar.n:  # (update: the time left from the recent rate, not from the start)
                self.bar.update(n - self.bar.n)
            else:
                self.bar.n = n
            self.bar.refresh()

    def phase(self, name: str, then: str | None = None):
        """Name what runs now ("compiling", "solving", "sampling 64 trajectories",
        "figures", ...): shown in the bar's description; starts the redrawing thread
        (interactive sessions only). ``then``: the name from the next solver step on
        (``phase("compiling", then="solving")``)."""
        self.phase_name, self._then = name, then
        if not self.enabled:
            return
        with self._lock:
            self._show()
            if self.bar is not None:
                self.bar.set_description_str(self._description())
        self._start_thread()

    def note(self, line: str):
        """Print ``line`` on the bar's stream above the bar (interactive sessions only)."""
        if not self.enabled or not line:
            return
        with self._lock:
            if self.bar is not None:
                self.bar.write(line, file=self.file)
            else:
                print(line, file=self.file, flush=True)

    def printing(self, log):
        """``log`` wrapped so that its lines (printed on stdout) do not break the bar: the
        bar is cleared for them and redrawn below."""
        def say(*args, **kwargs):
            if self.bar is None:
                return log(*args, **kwargs)
            from tqdm.auto import tqdm  # (see _show)
            with self._lock, tqdm.external_write_mode(file=sys.stdout):
                return log(*args, **kwargs)
        return say

    def close(self):
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=2.0)
        with self._lock:
            if self.bar is not None:
                self.bar.close()
                self.bar = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False
