"""Timing models: *when* a scheme's operations happen (cycles).

Fidelity levels are selected by name (``gpusim replay --fidelity NAME``); each
is a function ``(result, trace, gpu, reference) -> (record, image or None)``:

* ``analytic``: per-pass bounds from work / throughput and latency chains
  (gpusim.hw.timing);
* ``sampled``: the event model on a sample of screen tiles and on half of it,
  each pass extrapolated along the line through the two;
* ``full``: the discrete-event model of the GPU (gpusim.hw.machine) on every
  operation, with RMW hazards replayed into the image;
* ``thesis``: the execution-time model of seed 003 section 4.3.2 (one cycle per
  counted memory access plus the per-pixel compute cycles of [Amor06]), for
  the three schemes that thesis compares (gpusim.hw.thesis).
"""

from gpusim.hw.gpu import DEFAULT_GPU, GpuConfig, gpu_presets, load_gpu
from gpusim.hw.lower import Workload
from gpusim.hw.thesis import THESIS_RULES, thesis_timing
from gpusim.hw.timing import LEVELS


def _level(name):
    run = LEVELS[name]

    def fidelity(result, trace, gpu, reference=None):
        return run(Workload.of(result, trace), gpu, result, reference)
    fidelity.__name__ = f"{name}_timing"
    return fidelity


def _thesis(result, trace=None, gpu=None, reference=None):
    return thesis_timing(result), None


FIDELITIES = {"analytic": _level("analytic"), "sampled": _level("sampled"), "full": _level("full"),
              "thesis": _thesis}

__all__ = ["DEFAULT_GPU", "FIDELITIES", "GpuConfig", "THESIS_RULES", "Workload", "gpu_presets", "load_gpu",
           "thesis_timing"]
