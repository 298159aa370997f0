"""SLAM behind one interface: `make_slam("rbpf" | "odometry" | "graph", laser, params, rng)`."""
