"""Ready models.

- :mod:`models.pendulum` -- simple pendulum of paper sec. 5.1 (m = l = 1, g = 9.81).
- :mod:`models.double_pendulum` -- the paper's double pendulum, eq. (22), initial box
  (25), built three ways (hand-written eq. (22), DH chain with point masses, URDF).
- :mod:`models.planar` -- n-link planar chains (DH, standard or modified).
- :mod:`models.puma560` -- Puma 560 (Corke's DH table and inertial data), standard and
  modified DH.
- :mod:`models.robots` -- example-robot-data URDFs (double pendulum, UR5, panda arm).
"""
