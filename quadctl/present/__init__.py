"""One presenter: each stage result as rows and sentences, written once, for every output.

The terminal (:mod:`quadctl.cli.render`, rich styling only) and the run report
(:mod:`quadctl.report`, escaping and markup only) render the same :class:`~quadctl.present.cells.Table`
objects and sentences, so a number reads the same in both and comes from the same code.
Nothing here prints, reads a file or knows of rich or HTML: a table is a title, column headers
(units in them), rows of text cells and a caption; a sentence is a ``str``. A cell or sentence
that carries a verdict is a :class:`~quadctl.present.cells.Mark` (a ``str`` with a ``kind``:
``ok``, ``warning`` or ``fail``), which each renderer colours its own way.

=================  ==========================================================================
module             presents
=================  ==========================================================================
``cells``          the table and the verdict cell; the number formats (eigenvalues, dB, gains)
``stages``         trim, decoupling, controllability and observability; the check stage's verdicts
``design``         gains (K, Ki, Kv), K_block, the coupled closed loop as a damp table
``loops``          margins: classical, disk, delay; the LQR guarantee, the sampled loop, each finding
``flight``         a simulation's metrics, inputs, saturation, noise, estimation, wind, integrators
``schedule``       a gain schedule's points, envelope, frozen-point checks, verdict; a transition
``mission``        a flown reference: waypoints reached, closest approaches, the tracking error
=================  ==========================================================================
"""

from quadctl.present.cells import Mark, Table, db, eig, eigs, num, vector, weights

__all__ = ["Mark", "Table", "db", "eig", "eigs", "num", "vector", "weights"]
