"""The physical model: objects, grippers (parametric and MJCF), contact and solver settings,
the grasp procedure, the MuJoCo scene, pick-points and their metrics. Knows no engine and
writes no files.
"""
