"""Outward-rounded numbers: interval arrays and their compiled kernels, interval linear algebra,
exact numbers enclosed in doubles. The bottom room: imports nothing else of ``verified``.
"""
