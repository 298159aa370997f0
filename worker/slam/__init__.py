"""SLAM behind one interface (`base`): `registry.make_slam(name, laser, params, rng)`."""
