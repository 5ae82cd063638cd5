"""The execution-time model of seed 003 section 4.3.2 (the ``thesis`` fidelity level).

Execution time of the order-independent-transparency read-out = memory access
time + computation time, with

* one cycle per memory access, counting only the accesses the thesis counts:

  ============== =============================================================
  r-buffer       every R-buffer read in the recirculation passes, as many
                 second-z-buffer accesses, and one frame-buffer access per
                 blended fragment
  weight-factor  every M-buffer read (the pointer memory is read at the same
                 time as its section and costs nothing)
  tfss           every T-buffer read plus the SSA look-up that precedes it (the
                 NSA table is read at the same time as its section)
  ============== =============================================================

* computation per pixel with i stored fragments, as [Amor06] observes:
  i(i+1)/2 cycles for the R-buffer, i(i-1)/2 + 1 for Weight-Factor and TFSS
  (which adopts the weight-factor computation).

Accesses are taken from the scheme's own operation counts in its read passes
(``fullscreen`` and ``buffer`` passes), and i from the fragments each pixel
actually stored, so the model applies to any trace; on a trace whose
transparent fragments all survive early z and have distinct depths the memory
term reduces to the thesis's closed forms (sum N_i i(i+1)/2 reads for the
R-buffer, sum N_i i for the others).
"""

from __future__ import annotations

import numpy as np

from gpusim.errors import GpusimError

READ_PASS_KINDS = {"fullscreen", "buffer"}

#: scheme -> ((structure, operation) pairs that cost a cycle, compute-cycle formula name)
THESIS_RULES: dict[str, tuple[tuple[tuple[str, str], ...], str]] = {
    "r-buffer": ((("r_buffer", "load"), ("second_z_buffer", "depth_test"), ("framebuffer", "blend")),
                 "i(i+1)/2"),
    "weight-factor": ((("m_buffer", "load"),), "i(i-1)/2+1"),
    "tfss": ((("t_buffer", "load"), ("ssa_table", "load")), "i(i-1)/2+1"),
}


def compute_cycles(fragments_per_pixel: np.ndarray, formula: str) -> int:
    """Summed per-pixel computation cycles for pixels with at least one fragment."""
    i = np.asarray(fragments_per_pixel, np.int64)
    i = i[i > 0]
    if formula == "i(i+1)/2":
        return int((i * (i + 1) // 2).sum())
    if formula == "i(i-1)/2+1":
        return int((i * (i - 1) // 2 + 1).sum())
    raise ValueError(f"unknown compute formula {formula!r}")


def thesis_timing(result) -> dict:
    """Cycles of a ``tfss``, ``r-buffer`` or ``weight-factor`` result under section 4.3.2's model."""
    if result.scheme not in THESIS_RULES:
        raise GpusimError(f"--fidelity thesis models only {', '.join(sorted(THESIS_RULES))} "
                          f"(seed 003 section 4.3.2), not {result.scheme}; drop --fidelity for other schemes")
    counted, formula = THESIS_RULES[result.scheme]
    reads = result.plan.accesses(READ_PASS_KINDS)
    memory = {f"{s}.{op}": int(reads.get(s, {}).get(op, 0)) for s, op in counted}
    memory_cycles = sum(memory.values())
    compute = compute_cycles(result.extras["read_per_pixel"], formula)
    return {"fidelity": "thesis", "cycles": memory_cycles + compute, "memory_cycles": memory_cycles,
            "compute_cycles": compute, "compute_formula": formula, "counted_accesses": memory}
