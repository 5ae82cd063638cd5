"""Multi-fragment scheme models: what each scheme stores, reads, writes and updates.

Importing this package registers every scheme; select one by its CLI name with
:func:`make_scheme`. See gpusim.schemes.base for the interface and
gpusim.opplan for the operations a scheme reports.
"""

from gpusim.schemes import (  # noqa: F401  (importing registers each scheme)
    blending, bucket, depth_peeling, freepipe_abuffer, freepipe_mdts, kbuffer, linked_list, lucidraster, mboit, mlab,
    multipass_kbuffer, rbuffer, srab, tfss, weight_factor, zbuffer)
from gpusim.schemes.base import REGISTRY, Scheme, describe_scheme, make_scheme, scheme_class, scheme_names
from gpusim.schemes.result import SchemeResult

__all__ = ["REGISTRY", "Scheme", "SchemeResult", "describe_scheme", "make_scheme", "scheme_class",
           "scheme_names"]
