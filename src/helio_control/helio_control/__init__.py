"""
Planning and control of a painting.

Picture to ordered dots (paper Sec. IV-C, Eq 17) and the painting procedure
(Algorithm 1); nodes lens_planner and painter; the operator command line.
"""
