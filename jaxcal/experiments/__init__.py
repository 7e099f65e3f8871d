"""Experiments built on the calibration API: Monte Carlo studies, the paper's reproduction, and
the one timing helper they and the benchmarks share."""

from ._montecarlo import crlb_batch as crlb_batch
from ._montecarlo import crlb_variances as crlb_variances
from ._montecarlo import run_montecarlo as run_montecarlo
from ._montecarlo import study_sampler as study_sampler
from ._reproduce import run_reproduce as run_reproduce
from ._timing import cpu_model as cpu_model
from ._timing import machine_info as machine_info
from ._timing import summary as summary
from ._timing import timed as timed
