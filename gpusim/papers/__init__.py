"""Comparisons with the source papers ("Paper vs gpusim"), one module per seed, chosen by an experiment's
``paper`` key. Each module's ``compare(results, stats)`` returns a :class:`~gpusim.papers.base.Comparison`;
gpusim.report draws it. Nothing here imports matplotlib."""

from gpusim.papers import seed000, seed002, seed003, seed004, seed004_subdivision

#: name -> comparison module (``paper = "NAME"`` in an experiment file)
PAPERS = {"seed-000": seed000, "seed-002": seed002, "seed-003": seed003, "seed-004": seed004,
          "seed-004-subdivision": seed004_subdivision}


def paper_names() -> list[str]:
    return sorted(PAPERS)
