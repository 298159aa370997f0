"""SLAM behind one interface: `make_slam(name, laser, params, rng)`, names in `registry`."""
