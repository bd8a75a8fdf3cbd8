"""The particle filter node's TF side: amr_common.ros.map_odom_tf (shared with the SLAM node)."""
from amr_common.ros.map_odom_tf import MapOdomTf as LocalizationTf

__all__ = ["LocalizationTf"]
