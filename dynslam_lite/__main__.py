import os
import sys

# One BLAS thread unless the caller sets the variables (read when numpy loads): the methods'
# linear algebra is small (6 x 6 normal equations, local BA), and on 2 cores OpenBLAS's waiting
# threads take time from the rest. The batch's workers do the same (batch.one_blas_thread), so
# `run`, `bench` and `reproduce` measure alike; trajectories are identical either way.
for _var in ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

from .cli import main  # noqa: E402  (after the variables)

sys.exit(main())
