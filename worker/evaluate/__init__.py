"""Evaluation: SE(2) maths, trajectory files, relation generators, the relations metric, ATE."""
