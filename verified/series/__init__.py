"""Taylor series of ODE solutions: interval (:mod:`~verified.series.taylor`), affine
(:mod:`~verified.series.affine_taylor`) and Taylor-model (:mod:`~verified.series.taylor_model`)
coefficients over a set, and the variational equations as graphs.
"""
