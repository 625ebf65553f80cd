"""Scene generators for whole clusters: a seeded spherical cluster and a planar row."""
from .generate import ClusterSpec, RowSpec, cluster_scene, row_scene

__all__ = ["ClusterSpec", "RowSpec", "cluster_scene", "row_scene"]
