"""Dense-sampling oracle for reachable sets (scipy's DOP853 at tight tolerances): the
tests' name for :mod:`mbs.app.sampling`, its one home (the benchmarks import that module
itself). That module imports nothing from verified/ or the modeling core; see its
docstring for what is in it."""

from mbs.app.sampling import (SLACK, Ensemble, count_outside, dop853, end_states, hull_widths, in_union,
                              inside_union, line_points, misses, passive_plant, pinocchio_with,
                              plant_acceleration, sample_initial_points, sample_points, sample_trajectories,
                              states_at, trajectories)

__all__ = ["SLACK", "Ensemble", "count_outside", "dop853", "end_states", "hull_widths", "in_union",
           "inside_union", "line_points", "misses", "passive_plant", "pinocchio_with", "plant_acceleration",
           "sample_initial_points", "sample_points", "sample_trajectories", "states_at", "trajectories"]
