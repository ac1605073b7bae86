"""verified.warmup: the kernel warm-up runs, and its background process is handled."""
import subprocess
import sys

import pytest

from verified import warmup


def test_compile_kernels_runs_every_arithmetic():
    lines = []
    assert warmup.compile_kernels(log=lines.append) >= 0
    assert len(lines) == 8 and lines[0].startswith("warm: affine range") and "affine" in lines[2]
    assert "'model_degree': 4" in lines[-2]


def test_compile_kernels_warms_the_families_asked_for():
    lines = []
    warmup.compile_kernels(log=lines.append, families=("affine_range",))
    assert len(lines) == 1 and lines[0].startswith("warm: affine range")
    lines.clear()
    warmup.compile_kernels(log=lines.append, families=("interval",))
    assert [ln.split(" (")[0] for ln in lines] == ["warm: interval", "warm: batches, graph evaluation, interval operations"]
    with pytest.raises(ValueError, match="unknown kernel families .'afine'."):
        warmup.compile_kernels(families=("afine",))
    with pytest.raises(ValueError, match="unknown kernel families"):
        warmup.start_in_background(("afine",))


def test_background_warmup_can_be_turned_off(monkeypatch):
    monkeypatch.setenv("MBS_NO_WARMUP", "1")
    assert warmup.start_in_background() is None
    assert warmup.finish_background(None) == ""


def test_background_failures_and_overruns_are_reported_not_raised():
    bad = subprocess.Popen([sys.executable, "-c", "raise SystemExit(3)"])
    assert "exited with code 3" in warmup.finish_background(bad)
    slow = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    msg = warmup.finish_background(slow, timeout=0.2)
    assert "stopped after" in msg and slow.poll() is not None


def test_jobs_split_the_families_over_processes_and_name_a_failure(monkeypatch):
    started = []

    class Child:
        def __init__(self, cmd, env=None):
            started.append(cmd[3:])
            self.rc = 1 if cmd[3:] == ["affine"] else 0

        def wait(self):
            return self.rc
    monkeypatch.setattr(warmup.subprocess, "Popen", Child)
    with pytest.raises(RuntimeError, match="warm-up of affine failed"):
        warmup.compile_in_processes(2)
    assert started == [["Taylor-model"], ["affine"]]
    assert warmup._main(["--jobs"]) == 2 and warmup._main(["--jobs", "two"]) == 2
