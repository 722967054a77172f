"""The setpoints a Crazyflie app follows (``quadctl export --to crazyflie --setpoint``): what the commander
gives in each and the states each needs regulated. Kept apart from :mod:`quadctl.present` (which loads
numpy) so that the command line's help is built from them without loading it."""

SETPOINT_GIVES = {"position": "x, y, z, yaw", "velocity": "the hover setpoint: vx, vy, z, yaw rate"}
"""What the commander gives in each setpoint the Crazyflie app follows
(:data:`quadctl.export.crazyflie.SETPOINTS`)."""
SETPOINT_NEEDS = {"position": ("pN", "pE", "pD", "psi"), "velocity": ("u", "v", "pD", "psi")}
"""The states each setpoint needs regulated (in a subsystem with ``regulate: true``)."""
SETPOINT_OPTIONS = {s: f"--setpoint {s} ({gives})" for s, gives in SETPOINT_GIVES.items()}
"""Each setpoint as the option that asks for it, with what the commander gives."""
SETPOINT_HELP = (
    "--to crazyflie: the commander's setpoints the app follows: "
    + " or ".join(f"{s} ({gives}; needs {', '.join(SETPOINT_NEEDS[s])} regulated)"
                  for s, gives in SETPOINT_GIVES.items())
    + ". Default: the first of these the config's partition regulates (velocity for the bundled crazyflie, which "
      "leaves the position free).")
"""``quadctl export --setpoint``'s help."""
