"""Evaluation: SE(2) maths, trajectory files, relation generators, the relations metric, ATE.

Modules: `se2` (pose algebra), `trajectory` (Trajectory, lookup by time), `trajio` (CARMEN,
TUM and relations files), `relations` (Relations, generators A/B/SM/L/M/S), `metric`
(evaluate_relations, summary), `ate` (aligned absolute error); numba kernels live in
`lookup_kernels` and `relation_kernels`, bulk text parsing in `textio`.

Choices the thesis leaves open, made here: repeated timestamps keep the last sample; the
summary std is the population std (ddof 0), the B pilot std the sample std (ddof 1); M
measures the Euclidean distance from the last anchor (thesis 6.1), not the path length; L
keeps, for each returning pose, the nearest earlier pose it closes a loop with.
"""
