"""The sets the solver carries from step to step: the protocol the driver uses, first-order
(doubleton) and second-order sets, and the bases their error parts are kept in.
"""
