"""Paper A (depthcluster): depth clustering, depth-change pre-removal, dense odometry on the
static pixels with an iterative background update. One module per step."""
from .background import OutlierConfig, outliers, release, residuals
from .clustering import DepthClusters, cluster_count, cluster_depth, fill_edge_zeros, fill_holes
from .method import DepthClusterConfig, DepthClusterMethod, PairResult, estimate_pair
from .preremoval import PreRemoval, PreRemovalConfig, pre_remove

__all__ = [
    "OutlierConfig", "outliers", "release", "residuals", "DepthClusters", "cluster_count", "cluster_depth",
    "fill_edge_zeros", "fill_holes", "DepthClusterConfig", "DepthClusterMethod", "PairResult",
    "estimate_pair", "PreRemoval", "PreRemovalConfig", "pre_remove",
]
