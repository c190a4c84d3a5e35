"""Static-world odometry baselines: the dense solver paper A builds on, and OpenCV's peer."""
from .dense import DenseConfig, DenseResult, align
from .opencv_odometry import OpenCVOdometry, OpenCVOdometryConfig

__all__ = ["DenseConfig", "DenseResult", "align", "OpenCVOdometry", "OpenCVOdometryConfig"]
