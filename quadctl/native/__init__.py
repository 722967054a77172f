"""Native code as a service: C compiled once per machine and kept in the platform's cache folder.

- :mod:`~quadctl.native.compile`: find a compiler, compile a generated source under its cache key,
  load the library (:func:`~quadctl.native.compile.compile_cached`)
- :mod:`~quadctl.native.emit`: CasADi functions as C over ``lanes`` cases at once
- :mod:`~quadctl.native.pointwise`: a CasADi function over many points in its virtual machine
- :mod:`~quadctl.native.mapped`: the same compiled (a reference's rows, the feedforward's Newton solve)

It imports nothing of quadctl's but the lazy import of CasADi: the simulation's runners
(:mod:`quadctl.sim`), the Riccati doubling kernel (:mod:`quadctl.design.riccati.doubling`), the
feedforward (:mod:`quadctl.physics.flatness`), a reference's rows (:mod:`quadctl.physics.reference_rows`)
and a run's provenance all stand on it.
"""
