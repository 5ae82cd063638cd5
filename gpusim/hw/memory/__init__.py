"""The memory path: partitions, and the levels a request passes through (see gpusim.hw.memory.level).

Importing this package registers the ``memory`` section and the built-in
levels, in path order: ``coalescer``, ``l2``, ``dram``.
"""

from gpusim.hw.memory.level import MEMORY_OPS, SECTOR, MemoryConfig, MemoryLevel, Requests
from gpusim.hw.memory import coalescer, l2, dram  # noqa: F401,E402  (importing registers each level)

__all__ = ["MEMORY_OPS", "SECTOR", "MemoryConfig", "MemoryLevel", "Requests"]
