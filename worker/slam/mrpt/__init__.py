"""MRPT (mrpt-apps) as offline SLAM algorithms: the rawlog writer and the programs' runner."""
