"""A run's report: images with the metrics written on them, and plots of the trajectories."""
