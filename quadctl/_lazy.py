"""CasADi and SciPy imported on first use, so runs that need neither never pay for them.

``quadctl simulate`` on fresh artifacts with a cached compiled loop uses neither; importing
them costs ~0.3 s (CasADi ~0.1 s, ``scipy.linalg`` ~0.2 s) of a run that integrates a
million steps in ~0.2 s. A module binds ``ca = lazy_import("casadi")`` or
``scipy = lazy_import("scipy")`` and uses them as usual (``scipy.linalg`` then loads on first
access, as SciPy's own submodules do).
"""

from __future__ import annotations

import importlib.util
import sys
from types import ModuleType


def lazy_import(name: str) -> ModuleType:
    """Module ``name``, executed on its first attribute access (importlib's ``LazyLoader``).

    Returns the real module when it is already imported.

    Raises
    ------
    ModuleNotFoundError
        ``name`` is not installed (reported now, not at first use).
    """
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.find_spec(name)
    if spec is None or spec.loader is None:
        raise ModuleNotFoundError(f"No module named {name!r}", name=name)
    loader = importlib.util.LazyLoader(spec.loader)
    spec.loader = loader
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    loader.exec_module(module)
    return module
