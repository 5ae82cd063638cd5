"""The memory partitions and the interface of a memory level.

Memory is a chain of levels from the core outwards, named by ``memory.levels``
(default ``coalescer``, ``l2``, ``dram``); each level is a registered unit with
its own config section, one instance per memory partition, and a ``next``
level. A level that a config leaves out (an L2 of size 0) is skipped. To add a
level, subclass :class:`MemoryLevel` in a module of its own, register it, and
name it in ``memory.levels``:

* ``prepare(chunks, write)``: the coalesced requests that reach the level
  (:class:`Requests`, a run of whole instructions per chunk) before the run;
  a level that passes requests on unchanged hands them to ``next.prepare``;
* ``access(wi, arrive_fp, starts)``: serve instruction ``wi``'s requests
  arriving at sub-cycle ``arrive_fp``; the cycle the last one is back at the
  level's input. ``starts`` (a list per partition, or None) records the
  sub-cycle each partition started serving them, for the RMW-hazard analysis;
* ``request_costs(nbytes)`` and ``serve_request(partition, cost_fp, at_fp, held_fp, wi)``:
  one request of instruction ``wi`` from the level above (an L2 miss), the cycle it is back.

In a sampled program a request also stands for the rest of the GPU's requests
that came with it (:meth:`MemoryLevel.occupy`); each level decides where they
queue (gpusim.hw.background).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from gpusim.config import param
from gpusim.hw.unit import Unit, occupancy, register_section, run_held

MEMORY_OPS = frozenset({"load", "store", "rmw_read", "rmw_write"})
SECTOR = 32     # bytes: the granularity of a request's size


@dataclass(frozen=True)
class MemoryConfig:
    """Memory partitions: address interleaving, the core-partition interconnect, the memory path."""

    partitions: int = param(8, unit="partitions", doc="memory partitions (each holds one instance of every "
                            "memory level and one atomic unit)", min=1, max=1024)
    interleave_bytes: int = param(256, unit="bytes", doc="address interleave granularity across partitions",
                                  min=1)
    interconnect_latency: int = param(20, unit="cycles", doc="core to partition latency (each way)", min=0)
    levels: tuple[str, ...] = param(("coalescer", "l2", "dram"), doc="the memory path from the core outwards: "
                                    "registered memory levels, first the one that takes the core's requests, "
                                    "last a memory")


register_section("memory", MemoryConfig)


@dataclass
class Requests:
    """Coalesced requests of a run of whole instructions, in the order the program stores them."""

    rank: np.ndarray          # the position in ``order`` of each request's instruction (ascending)
    order: np.ndarray         # the memory instructions in storage order (shared by every chunk)
    partition: np.ndarray
    address: np.ndarray       # byte address of the request's segment
    nbytes: np.ndarray

    @property
    def wi(self) -> np.ndarray:
        """The instruction of each request."""
        return self.order[self.rank]


class MemoryLevel(Unit):
    """A level of the memory path, one instance per partition (see the module docstring)."""

    reached = MEMORY_OPS
    terminal: ClassVar[bool] = False          # a memory: requests end here
    parent = "memory"

    def __init__(self, machine):
        super().__init__(machine.gpu.memory.partitions)
        self.next: MemoryLevel | None = machine.level_after(self.name)
        self.free = [0] * self.instances      # sub-cycle each instance is free
        self.program = getattr(machine, "program", None)
        if self.program is not None and self.program.occupancy is not None:
            self.run_busy_fp = [0] * self.instances

    def occupy(self, cost_fp: np.ndarray, wi: np.ndarray, partition: np.ndarray, mine: bool = True) -> np.ndarray:
        """How long requests of ``cost_fp`` from instructions ``wi`` hold ``partition`` (gpusim.hw.unit.occupancy:
        their cost, in a sampled program the run's share of the partition's traffic); ``mine``: requests this
        level serves (counted in :attr:`run_busy_fp`), not the next level's."""
        if self.program is None or self.program.occupancy is None:
            return cost_fp
        pass_of = self.program.wi_pass[wi]
        held = occupancy(cost_fp, pass_of, partition, self.program, "memory")
        if mine:
            run = np.bincount(partition, weights=run_held(held, pass_of, self.program, "memory"),
                              minlength=self.instances)
            self.run_busy_fp = (np.asarray(self.run_busy_fp) + run).tolist()
        return held

    @classmethod
    def needed(cls, program, gpu) -> bool:
        """On the path and present, and reached: by the core's memory operations, or by the ROPs' framebuffer
        traffic (gpusim.hw.rop)."""
        from gpusim.hw.rop import framebuffer_operations
        framebuffer = bool(framebuffer_operations(gpu) & program.operation_names())
        return (cls.name in gpu.memory.levels and cls.present(getattr(gpu, cls.name))
                and (framebuffer or super().needed(program, gpu)))

    @classmethod
    def present(cls, config) -> bool:
        """Whether a config with this section has the level at all."""
        return True

    def prepare(self, chunks: list[Requests], write: np.ndarray) -> None:
        """The requests reaching this level; ``write[wi]``: whether instruction ``wi`` writes."""
        self.next.prepare(chunks, write)

    def access(self, wi: int, arrive_fp: int, starts: list | None) -> int:
        raise NotImplementedError

    def request_costs(self, nbytes: np.ndarray) -> np.ndarray:
        raise NotImplementedError(f"{self.name} cannot sit behind a level that sends single requests")

    def serve_request(self, partition: int, cost_fp: int, at_fp: int, held_fp: int, wi: int) -> int:
        """Serve one request of instruction ``wi`` of ``cost_fp`` sub-cycles arriving at ``at_fp``; it stands
        for ``held_fp`` of the partition's time (:meth:`occupy`); the cycle its data is back."""
        raise NotImplementedError(f"{self.name} cannot sit behind a level that sends single requests")

    def idle_at(self) -> int:
        return -(-max(self.free) // (1 << 16))
