"""The Taylor-model kernel's work memory: a batch that cannot fit the machine is a clear
error (an experiment once asked numpy for a 37.6 GiB buffer)."""

import pytest

import verified.series.taylor_model as tm_mod
from verified.graph import trace


def test_work_memory_beyond_the_machine_is_a_clear_error(monkeypatch):
    """A batch whose kernel work arrays exceed the machine's memory is refused with a
    one-line MemoryError naming the sizes, not numpy's allocation failure."""
    ode = tm_mod.TaylorModelODE(trace(lambda x, p: [x[1], -x[0]], 2, 0))
    monkeypatch.setattr(tm_mod, "_memory_bytes", lambda: 2.0**30)
    with pytest.raises(MemoryError, match=r"needs .* GiB of work memory \(100000 sets"):
        ode._work(50, 12, 100_000, 300)
    F, REC = ode._work(5, 4, 2, 10)   # (a small batch still gets its arrays)
    assert F.shape == (5, 5, 2, 10) and REC.shape == (5, 2, 10)
