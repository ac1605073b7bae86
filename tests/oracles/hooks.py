"""Hooks the tests hand to runs (picklable: module level, so Dask workers can load them)."""
import time

from verified.driver.hooks import Hook


class SlowSteps(Hook):
    """Sleep after every step (so that a worker can be killed while it holds a chunk)."""

    def __init__(self, seconds):
        self.seconds = seconds

    def after_step(self, step, sets, run):
        time.sleep(self.seconds)
        return None
