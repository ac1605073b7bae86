"""The loop of one in-process batch (:mod:`~verified.driver.batch`) and what it is made of: the
step/wrap/split/merge controls, hooks, argument checks, the Solution and runs continued in time.
"""
