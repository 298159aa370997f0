"""The pipeline: worlds, simulator, exploration, SLAM and evaluation (pure numpy/numba)."""
