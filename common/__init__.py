"""The toolkit's ground floor: strict configs, atomic file output and locks, image I/O, checkpoints,
colour conversions, image metrics and run provenance. It imports no other package of the project."""

import os

__version__ = "0.2.0"

# Idle OpenMP threads (torch's and numba's pools) sleep instead of spinning: on a machine shared with
# other work, spinning threads made a 2-thread deformation step 2x slower than one thread, while on an
# idle machine sleeping costs nothing measurable (docs/design/recon.md, "Threads"). OpenMP reads this once,
# when torch or numba first loads it, so it is set here, on the floor every package imports first;
# a value the user set is kept.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
