"""Old import paths of modules that moved, kept working: each is the module that moved, not a copy.

``import quadctl.setup`` gives :mod:`quadctl.problem` itself (so ``quadctl.setup.Setup is
quadctl.problem.Setup``), ``quadctl.riccati.stacked`` gives :mod:`quadctl.lqr.riccati.stacked`.
No file stays at an old path: :func:`install` (run by ``import quadctl``) puts one finder first on
:data:`sys.meta_path` that answers exactly the names in :data:`MOVED` and the modules under them.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys

MOVED = {
    "quadctl.setup": "quadctl.problem",
    "quadctl.simulate": "quadctl.sim.run",
    "quadctl.discrete": "quadctl.lqr.discrete",
    "quadctl.riccati": "quadctl.lqr.riccati",
}
"""Old module path -> where the module lives now."""


def new_name(name: str) -> str | None:
    """Where module ``name`` lives now, or None if it did not move.

    >>> new_name("quadctl.riccati.stacked"), new_name("quadctl.lqr.riccati"), new_name("quadctl.setuptools")
    ('quadctl.lqr.riccati.stacked', None, None)
    """
    for old, new in MOVED.items():
        if name == old or name.startswith(old + "."):
            return new + name[len(old):]
    return None


class _MovedFinder(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Finds an old path and loads it as the module at its new path (imported once, one object)."""

    def __init__(self):
        self._specs: dict = {}

    def find_spec(self, name, path=None, target=None):
        if new_name(name) is None:
            return None
        return importlib.util.spec_from_loader(name, self)

    def create_module(self, spec):
        module = importlib.import_module(new_name(spec.name))  # its name, file and loader stay its own
        self._specs[module.__name__] = module.__spec__
        return module

    def exec_module(self, module):
        module.__spec__ = self._specs[module.__name__]  # the import system set the old path's spec: undone


def install() -> None:
    """Put the finder first on :data:`sys.meta_path` (once)."""
    if not any(isinstance(f, _MovedFinder) for f in sys.meta_path):
        sys.meta_path.insert(0, _MovedFinder())
