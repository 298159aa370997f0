"""The robot simulator: laser ray casting, differential drive, odometry, CARMEN logs."""
