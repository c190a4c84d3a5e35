"""Paper B (weightedstatic): semantic static points, the weighted geometric constraint, and the
joint optimisation of pose and per-point static weights. One module per step."""
from .geometric import GeometricConfig, GeometricTest, rays, weighted_geometric_test
from .method import WeightedStaticConfig, WeightedStaticMethod, WeightedStaticTracker
from .weighted_ba import JointResult, initial_weights, joint_cost, joint_pose_and_weights

__all__ = [
    "GeometricConfig", "GeometricTest", "rays", "weighted_geometric_test", "WeightedStaticConfig",
    "WeightedStaticMethod", "WeightedStaticTracker", "JointResult", "initial_weights", "joint_cost",
    "joint_pose_and_weights",
]
