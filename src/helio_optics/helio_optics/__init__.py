"""
Optics, sun estimation and kinematics of the helio rig.

Lens ray tracing (paper Eqs 1-6), spot features (Eq 10), sun-orientation estimation
(Eqs 11-12), ephemeris (Eq 18), lens pose and arm kinematics (Eqs 14-15); node
sun_estimator.
"""
