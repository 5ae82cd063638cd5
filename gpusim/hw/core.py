"""SIMT cores (streaming multiprocessors): warps, their scheduler, the issue port, latency hiding.

Each SM runs up to ``core.warps_per_sm`` resident warps. A pass's warps go to
the SMs round robin in submission order (:meth:`SimtCore.place`, the one place
SM placement is decided; every stat and the analytic level use it), and a
finished warp's slot takes its SM's next warp. Each resident-warp slot is a
simpy process that runs its warps one after the other.

A warp issues its instructions in program order through its scheduler's issue
port (an SM has ``core.schedulers``, each over its share of the lanes; a
resident-warp slot belongs to one; warps take a port in the order they ask for
it). A memory instruction and
the ``core.instructions_per_op`` ALU instructions around it hold the port for
``issue_cycles`` plus the ALU instructions' cycles; a :class:`Compute`
instruction (triangle setup, a scheme's ALU work) for its own cycles. ALU
instructions issue ``core.alu_issue_width`` per lane and cycle (1 on a scalar
SIMT lane; a G71 pixel pipeline's two co-issuing vec4 units issue 4). An
instruction that depends on the thread's previous result waits for it, and
other warps of the SM issue meanwhile (latency hiding). A unit that cannot
take an instruction yet (a full reorder buffer, a busy scoreboard cell) hands
back a simpy event; the warp waits for it and issues the instruction again.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Literal

import numpy as np

from gpusim.config import param
from gpusim.hw.program import COMPUTE
from gpusim.hw.unit import Unit, occupancy_stats, register_unit


@dataclass(frozen=True)
class CoreConfig:
    """SIMT cores (streaming multiprocessors) and their warp schedulers."""

    sms: int = param(30, unit="SMs", doc="streaming multiprocessors", min=1, max=4096)
    warp_size: int = param(32, unit="threads", doc="threads per warp", min=1, max=1024)
    lanes_per_sm: int = param(8, unit="lanes", doc="scalar lanes per SM (a warp instruction issues over "
                              "warp_size / (lanes_per_sm / schedulers) cycles on its scheduler's lanes)", min=1)
    schedulers: int = param(1, unit="schedulers", doc="warp schedulers per SM, each issuing one warp instruction "
                            "at a time to its own lanes_per_sm / schedulers lanes; a resident-warp slot belongs to "
                            "scheduler slot % schedulers: 1 on GT200 and G71, 4 on Ampere and Hopper (their SMs' "
                            "four processing blocks, NVIDIA's GA102 and H100 whitepapers)", min=1, max=16)
    warps_per_sm: int = param(32, unit="warps", doc="resident warps per SM (latency hiding)", min=1, max=1024)
    clock_mhz: float = param(1296.0, unit="MHz", doc="shader clock: the model's cycle", gt=0)
    instructions_per_op: int = param(4, unit="instructions", doc="ALU instructions a thread issues per memory "
                                     "operation (address arithmetic, the shader or rasterizer work around it)",
                                     min=0)
    alu_issue_width: int = param(1, unit="instructions/lane/cycle", doc="scalar ALU instructions a lane issues "
                                 "per cycle (the ALU instructions around a memory operation and a scheme's "
                                 "declared ALU work; a memory instruction still takes a cycle of the lane): 1 for "
                                 "a scalar SIMT lane (GT200 and later, whose lanes are the count); 4 for a "
                                 "G70/G71 pixel pipeline, two vec4 shader units in series (dual issue), each "
                                 "co-issuing two instructions on a 3+1 or 2+2 split of its components (GPU Gems "
                                 "2 ch. 30; NVIDIA's NV40/G70 disclosures: 4 instructions per pixel per clock); "
                                 "the schemes' scalar counts are taken as independent work a compiler packs",
                                 min=1, max=8)
    thread_mapping: Literal["auto", "fragment", "triangle"] = param(
        "auto", doc="thread of a geometry pass: one per fragment, one per triangle (FreePipe: the thread "
                    "rasterizes its triangle and issues its fragments' operations in turn), or auto "
                    "(triangle for software-pipeline passes, fragment for the graphics pipeline)")
    pipeline_latency: int = param(200, unit="cycles", doc="cycles to drain the pipeline at a flush "
                                  "(a pass boundary that waits for all work)", min=0)

    def __post_init__(self) -> None:
        if self.warp_size & (self.warp_size - 1) or not 1 <= self.warp_size <= 1024:
            raise ValueError(f"warp_size: must be a power of two from 1 to 1024 threads (e.g. 32), "
                             f"got {self.warp_size}")
        if self.lanes_per_sm % self.schedulers:
            raise ValueError(f"schedulers: must divide lanes_per_sm = {self.lanes_per_sm} (each scheduler has its "
                             f"own share of the lanes), got {self.schedulers}")

    @property
    def issue_cycles(self) -> int:
        """Cycles one warp instruction occupies its scheduler's issue port (over that scheduler's lanes)."""
        return -(-self.warp_size // (self.lanes_per_sm // self.schedulers))

    @property
    def issue_ports(self) -> int:
        """Issue ports of the whole GPU (an SM's schedulers each have one)."""
        return self.sms * self.schedulers

    def alu_cycles(self, instructions):
        """Issue-port cycles of a warp's ``instructions`` ALU instructions (an int or an integer array): each
        lane issues ``alu_issue_width`` of them a cycle, rounded up to whole cycles."""
        return -(-(instructions * self.issue_cycles) // self.alu_issue_width)

    @property
    def op_issue_cycles(self) -> int:
        """Issue-port cycles of a memory instruction and the ALU instructions around it."""
        return self.issue_cycles + self.alu_cycles(self.instructions_per_op)


@register_unit
class SimtCore(Unit):
    """The SMs of the GPU; one instance per SM."""

    name = "core"
    Config = CoreConfig
    STATS = occupancy_stats("cycles the SM's issue port was held", "instructions",
                            "warp instructions issued (memory and compute)")

    def __init__(self, config: CoreConfig, machine):
        super().__init__(config.sms)
        self.config, self.machine, self.env = config, machine, machine.env
        prog = machine.program
        self.sm_free = [0] * config.issue_ports      # cycle each scheduler's issue port is free (SM-major)
        self.last_progress = 0                       # cycle of the last issue
        self.done = 0                                # cycle the pass's last operation completes
        self.waiting: dict[int, tuple] = {}          # warp -> (pass, SM, instruction, unit, event) it waits on
        self.running = 0                             # warps taken by a slot and not finished
        self.warps_done = 0
        # per instruction: (unit, depends, produces, issue cycles), as one list the slots index once each
        self._instructions = list(zip(prog.wi_unit.tolist(), prog.wi_dep.tolist(), prog.wi_produces.tolist(),
                                      prog.wi_cycles.tolist()))
        # port occupancy and instructions per SM (static: where each warp runs is fixed)
        sm = np.zeros(prog.instructions, np.int64)
        for p in prog.passes:
            if p.warps:
                lo, hi = int(p.wi_start[0]), int(p.wi_start[-1])
                sm[lo:hi] = self.place(p.warps, config.sms)[prog.wi_warp[lo:hi] - p.first_warp]
        cyc = prog.wi_cycles
        # an SM's busy cycles: its ports' over its schedulers (all of them issuing: the SM busy every cycle)
        self.busy_fp = (np.bincount(sm, weights=cyc, minlength=config.sms) * ((1 << 16) / config.schedulers)
                        ).astype(np.int64).tolist()
        self.requests = np.bincount(sm, minlength=config.sms).tolist()

    @staticmethod
    def place(warps: int, sms: int) -> np.ndarray:
        """The SM of each of a pass's ``warps`` (round robin in submission order)."""
        return np.arange(warps, dtype=np.int64) % sms

    def flush_cycles(self) -> int:
        return flush_cycles(self.config)

    def start_pass(self, p, ready, serve: list) -> list:
        """Start the slot processes of pass ``p`` at the current cycle; the processes.

        ``ready[w]``: the cycle warp ``w`` (in the pass) may start (its triangles rasterized), or None;
        ``serve[u]``: the ``serve`` method of unit ``u`` of the program."""
        sms, slots = self.config.sms, self.config.warps_per_sm
        sm_of = self.place(p.warps, sms)
        by_sm = np.argsort(sm_of, kind="stable")
        bounds = np.searchsorted(sm_of[by_sm], np.arange(sms + 1)).tolist()
        wi_start = p.wi_start.tolist()
        procs = []
        for sm in range(sms):
            queue = deque(by_sm[bounds[sm]:bounds[sm + 1]].tolist())     # the SM's warps in submission order
            for slot in range(min(slots, len(queue))):
                port = sm * self.config.schedulers + slot % self.config.schedulers
                procs.append(self.env.process(self._slot(p, sm, port, queue, wi_start, ready, serve)))
        return procs

    def _slot(self, p, sm: int, port: int, queue: deque, wi_start: list, ready, serve: list):
        """One resident-warp slot of SM ``sm``, issuing through scheduler port ``port``: takes the SM's next
        waiting warp until none is left.

        Times are integers and a timeout of ``d`` resumes exactly ``d`` later, so ``now`` is kept here and
        read from the environment only after waiting on a unit's event."""
        env = self.env
        timeout = env.timeout
        instructions = self._instructions
        sm_free = self.sm_free
        hooks = self.machine.warp_end_hooks
        first = p.first_warp
        while queue:
            w = queue.popleft()
            key = env.key = first + w                # its events come in warp order among simultaneous ones
            self.running += 1
            now = env.now
            t = ready[w] if ready is not None and ready[w] > now else now
            yield timeout(t - now)                   # a queue entry even at once: warps start in order
            env.key = key
            now = t
            value = done = now
            lo = wi_start[w]
            for wi, (u, dep, produces, cyc) in enumerate(instructions[lo:wi_start[w + 1]], lo):
                if u == COMPUTE:                     # ALU work: holds the port, the next instruction waits
                    if dep and value > now:          # it works on a loaded value: wait for it
                        yield timeout(value - now)
                        env.key = key
                        now = value
                    f = sm_free[port]
                    sm_free[port] = (f if f > now else now) + cyc
                    if sm_free[port] > self.last_progress:     # issuing ALU work is progress (the watchdog)
                        self.last_progress = sm_free[port]
                    continue
                if dep and value > now:              # wait for the result it depends on
                    yield timeout(value - now)
                    env.key = key
                    now = value
                f = sm_free[port]
                if f > now:                          # the issue port is taken until f
                    sm_free[port] = f + cyc
                    yield timeout(f - now)
                    env.key = key
                    now = f
                else:
                    sm_free[port] = now + cyc
                d = serve[u](wi, now)
                while type(d) is not int:            # the unit cannot take it yet: wait, then issue again
                    self.waiting[first + w] = (p.name, sm, wi, self.machine.program.units[u], d)
                    if len(self.waiting) == self.running:
                        self.machine.all_waiting()
                    yield d
                    del self.waiting[first + w]
                    env.key = key                    # woken: retry in warp order among this cycle's events
                    yield timeout(0)
                    env.key = key
                    now = env.now
                    d = serve[u](wi, now)
                self.last_progress = now
                if produces:
                    value = d
                if d > done:
                    done = d
            self.running -= 1
            self.warps_done += 1
            if done > self.done:
                self.done = done
            for hook in hooks:
                hook(first + w, done)
            if self.waiting and len(self.waiting) == self.running:    # the others all wait
                self.machine.all_waiting()

    def idle_at(self) -> int:
        return max(self.sm_free)

    def line_trace(self) -> str:
        return (f"core: last issue at {self.last_progress} waiting={len(self.waiting)} "
                + " ".join(f"[{i}] free={f}" for i, f in enumerate(self.sm_free[:8])))


def flush_cycles(core: CoreConfig) -> int:
    """A flush: the pipeline drains (``pipeline_latency``). The full-screen quad that forces it (colour writes
    masked) shades no pixel: seed 004's Table 1 puts a batch and its flush at 11.4-11.8 us for Dragon on the
    GeForce 7900 GTX, less than its 24 pixel pipelines need to shade a 512x512 quad once (16.8 us); see
    docs/timing-model.md ("The papers' orderings")."""
    return core.pipeline_latency
