"""Ground truth and error: the exact reference compositor and image error metrics."""

from gpusim.metrics.error import image_error
from gpusim.metrics.reference import composite_exact, depth_order

__all__ = ["composite_exact", "depth_order", "image_error"]
