"""Tests and contractors that cut impossible parts out of enclosures: the energy test and its
pieces (reduction area, branch and prune, backward test, energy contraction and shell),
invariants, conservation laws, contractors (paper sec. 4; issues 13, 14, 40, 43).
"""
