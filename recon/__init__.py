"""Dynamic scene reconstruction: `fit` a registered method (a `TrainResult`), `load` a model, `model.render(camera, t)`,
`evaluate` it on a scene's held-out views."""
import common  # noqa: F401  (first: it sets the OpenMP wait policy before torch or numba loads)
from recon.api import TrainResult, evaluate, fit, load, resolve_config  # noqa: F401
from recon.methods import get_method, method_names  # noqa: F401
