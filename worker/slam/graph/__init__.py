"""Graph-based SLAM (the Karto / slam_toolbox and Cartographer family) behind the Slam protocol."""
