"""gpusim: a cycle-approximate simulator of GPU hardware for multi-fragment rendering.

Data path (see DESIGN.md): scene -> :mod:`gpusim.raster` -> :class:`FragmentTrace`
-> schemes -> hardware timing -> :mod:`gpusim.metrics` -> reports.
"""

from gpusim.errors import GpusimError
from gpusim.trace import FragmentTrace

__version__ = "0.1.0"
__all__ = ["FragmentTrace", "GpusimError", "__version__"]
