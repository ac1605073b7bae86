"""Public name for the Pinocchio comparison: ``mbs.check.compare_with_pinocchio``."""
from .pinocchio_check import (compare_with_pinocchio, to_pinocchio, pinocchio_reference,
                              random_states, max_error, format_report)

__all__ = ["compare_with_pinocchio", "to_pinocchio", "pinocchio_reference", "random_states",
           "max_error", "format_report"]
