"""CasADi and SciPy imported on first use, so runs that need neither never pay for them.

``quadctl simulate`` on fresh artifacts with a cached compiled loop uses neither; importing
them costs ~0.3 s (CasADi ~0.1 s, ``scipy.linalg`` ~0.2 s) of a run that integrates a
million steps in ~0.2 s. A module binds ``ca = lazy_import("casadi")`` or
``scipy = lazy_import("scipy")`` and uses them as usual (``scipy.linalg`` then loads on first
access, as SciPy's own submodules do).

Not importlib's ``LazyLoader``: on Python 3.11 a second thread can see its module half-loaded
(a Dask worker runs several sweep chunks in threads). Here the first access imports the real
module under a lock, by the normal import system, and nothing is put in ``sys.modules``.
"""

from __future__ import annotations

import importlib
import importlib.util
import sys
import threading
from types import ModuleType


class LazyModule(ModuleType):
    """Stands for module ``name`` until an attribute is read, then imports it (thread-safe)."""

    def __init__(self, name: str):
        super().__init__(name)
        self.__dict__["_lock"] = threading.Lock()

    def __getattr__(self, attr: str):  # only for attributes not yet copied from the real module
        with self.__dict__["_lock"]:
            if "_module" not in self.__dict__:
                module = importlib.import_module(self.__name__)
                self.__dict__.update(module.__dict__)
                self.__dict__["_module"] = module
        return getattr(self.__dict__["_module"], attr)


def lazy_import(name: str) -> ModuleType:
    """Module ``name``, imported on its first attribute access (at once if already imported).

    Raises
    ------
    ModuleNotFoundError
        ``name`` is not installed (reported now, not at first use).
    """
    if name in sys.modules:
        return sys.modules[name]
    if importlib.util.find_spec(name) is None:
        raise ModuleNotFoundError(f"No module named {name!r}", name=name)
    return LazyModule(name)
