"""Native code as a service: C compiled once per machine and kept in the platform's cache folder.

- :mod:`~quadctl.native.compile`: find a compiler, compile a generated source under its cache key,
  load the library (:func:`~quadctl.native.compile.compile_cached`)

It imports nothing of quadctl's: the simulation's runners (:mod:`quadctl.sim`), the Riccati
doubling kernel (:mod:`quadctl.design.riccati.doubling`) and a run's provenance all stand on it.
"""
