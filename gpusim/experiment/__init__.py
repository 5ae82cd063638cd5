"""Config-driven experiments: a sweep is data (configs/experiments/*.toml), results are tables.

* :mod:`~gpusim.experiment.spec`: experiment files, ``include`` overlays, ``--set``, validation;
* :mod:`~gpusim.experiment.grid`: the run grid and run ids;
* :mod:`~gpusim.experiment.execute`: one task (a functional model run and its timed runs);
* :mod:`~gpusim.experiment.executors`: this process, local worker processes, or a dask cluster;
* :mod:`~gpusim.experiment.store`: the output directory, resume, the results tables;
* :mod:`~gpusim.experiment.runner`: a whole sweep.

Reports (gpusim.report) read only the tables these write.
"""

from gpusim.experiment.grid import RunSpec, expand, run_id
from gpusim.experiment.runner import Summary, describe_summary, run_experiment
from gpusim.experiment.spec import DEFAULT_EXPERIMENT, Experiment, load_experiment

__all__ = ["DEFAULT_EXPERIMENT", "Experiment", "RunSpec", "Summary", "describe_summary", "expand",
           "load_experiment", "run_experiment", "run_id"]
