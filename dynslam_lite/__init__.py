"""dynslam_lite: visual odometry/SLAM in dynamic indoor scenes, companion to three papers.

Layers: ``geometry`` (pure maths), ``io`` (TUM/Bonn sequences, trajectories), ``evaluation``
(evo ATE/RPE, mask metrics), ``synth`` (synthetic benchmark), ``odometry`` (static baselines),
and one subpackage per paper.
"""
__version__ = "0.1.0"
