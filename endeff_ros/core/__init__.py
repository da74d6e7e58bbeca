"""Algorithm core of endeff_ros: numpy, scipy and OpenCV only, never rclpy.

Where things are:

- ``params``       the typed parameter set (paper symbols)
- ``types``        frames, intrinsics and results (frozen dataclasses)
- ``cloud``        depth + K -> points, foreground box, floor removal, voxels (Section 3)
- ``bands``        narrow-band level-set expansion and sub-bands (Section 4.1, Eqs. 1-4)
- ``graph``        topology graph, root, iterated Dijkstra, geodesics (Section 4.2, Eqs. 5-7)
- ``single_frame`` the Section 4 estimator: frame in, end-effector candidates out
- ``candidates``   the candidate scorer: over-generated extremes kept by their evidence
- ``flow``         optical flow and 3D scene flow (Section 5.1)
- ``tracker``      predict-update tracker (Section 5, Eqs. 7-9)
"""
