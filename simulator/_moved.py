"""Old import paths of the event-file modules, which moved to `eventio` in 0.2 (kept until 0.3).

`simulator.h5io` and its siblings are the `eventio` modules themselves (one module object, so
monkeypatching either name patches both); importing one by its old name warns once.
"""
from __future__ import annotations

import importlib
import sys
import warnings


def alias(old: str, new: str) -> None:
    """Make module `old` the already-importable module `new`, with a deprecation line."""
    from common.deprecations import kept_until

    warnings.warn(f"`{old}` moved to `{new}`; the old name keeps working until {kept_until('module', old)}",
                  FutureWarning, stacklevel=3)
    sys.modules[old] = importlib.import_module(new)
