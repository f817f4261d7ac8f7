"""
Perception of the light spot and of the heated wood.

RGB light-spot detection on the ground plane with the ArUco homography (paper Eqs 7-10)
and thermal pyrolysis statistics (Sec. IV-B); nodes spot_detector and thermal_monitor.
"""
