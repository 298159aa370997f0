"""ROS bags out (a run's or a CARMEN log's sensor data) and estimates in (scored on a run)."""
