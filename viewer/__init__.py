"""The browser viewer (`e4dgs viewer`): a dataset's cameras and frames, trained runs rendered live."""
import common  # noqa: F401  (first: it sets the OpenMP wait policy before torch or numba loads)
