"""The operating point and the linear model about it.

- :mod:`~quadctl.linear.trim`: the equilibrium (trim) of a flight condition, one or many
- :mod:`~quadctl.linear.linearize`: the Jacobians about a trim (with the reference drift)
"""
