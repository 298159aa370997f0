"""SLAM behind one interface: `make_slam("rbpf" | "odometry", laser, params, rng)`."""
