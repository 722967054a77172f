"""The quadctl exception hierarchy.

Every error a user can cause is a :class:`QuadctlError`; its message is one line that
names the problem and the fix. ``exit_code`` is what the command line returns:
2 for bad input, 1 for valid input whose design fails a check. A Python call's wrong argument is an
:class:`ArgumentError` (a ``ValueError``) or an :class:`ArgumentTypeError` (a ``TypeError``), so that
``except ValueError`` and ``except qc.QuadctlError`` both catch it.
"""

from __future__ import annotations


class QuadctlError(Exception):
    """Base class of every error quadctl raises on purpose.

    Examples
    --------
    Catch it to handle any input quadctl refuses; ``exit_code`` is what the command line returns.

    >>> import quadctl as qc
    >>> try:
    ...     qc.load_config("no-such-config")
    ... except qc.QuadctlError as exc:
    ...     print(type(exc).__name__, exc.exit_code)
    ConfigError 2
    """

    exit_code = 2
    from_config = False
    """The config's values caused it, but the message does not name the file (the stage that
    raised it got numbers, not a file): the command line puts the file in front."""


class ConfigError(QuadctlError, ValueError):
    """A config file or value is invalid (names the file, key path, value and fix).

    Examples
    --------
    >>> import quadctl as qc
    >>> qc.load_config("hoover")
    Traceback (most recent call last):
    ...
    quadctl.errors.ConfigError: hoover: no such file and no bundled config of that name; did you mean `hover`? ...
    """

    key: str | None = None
    """The key path the message is about, when one key is (``simulation.initial_offset.foo``)."""


class ArgumentError(QuadctlError, ValueError):
    """A Python call's argument has a value quadctl cannot take (a negative ``dt``, an unknown
    ``to``, a start of the wrong shape): the message names the call, the argument, what was expected
    and what was found. A ``ValueError`` too, as SciPy's and NumPy's users expect.

    Examples
    --------
    >>> import quadctl as qc
    >>> qc.Vehicle(mass=0.0)
    Traceback (most recent call last):
    ...
    quadctl.errors.ArgumentError: Vehicle: mass (kg) and the inertia's diagonal (kg m^2) must be positive, ...
    """


class ArgumentTypeError(QuadctlError, TypeError):
    """A Python call got an object of the wrong kind where it takes one of quadctl's (a config's name
    where a :class:`~quadctl.config.schema.Config` goes): the message names what to pass. A
    ``TypeError`` too.

    Examples
    --------
    >>> import quadctl as qc
    >>> qc.setup_of("hover")
    Traceback (most recent call last):
    ...
    quadctl.errors.ArgumentTypeError: setup_of takes a validated Config, qc.setup_of(qc.load_config('hover')); got str
    """


class ArtifactError(QuadctlError, OSError):
    """An artifact cannot be written, or an existing one is corrupt or foreign."""


class ActuatorLimitError(ConfigError):
    """The trim needs more (or less) than the configured actuator limits allow: the config's
    values conflict, found by a stage that has numbers, not the file."""

    from_config = True


class RateError(ConfigError):
    """A command's rate (``--rate``) and the config's ``controller.rate`` disagree, or a command that
    samples (``export --to c``) gets neither: found from the setup, not the file."""

    from_config = True


class SweepError(QuadctlError, ValueError):
    """A sweep file is invalid."""


class ScheduleError(ConfigError):
    """A gain schedule the config's values cannot make (too few values trim, or the config's own
    flight condition outside the envelope): found by the schedule stage, which has numbers, not the file."""

    from_config = True


class TrimError(QuadctlError, ValueError):
    """No equilibrium exists for the flight condition, or the solver did not find it.

    Examples
    --------
    A climb so fast that the rotor drag along body z outgrows the thrust has no equilibrium:

    >>> import quadctl as qc
    >>> qc.trim([0, 0, -10], 0.0, [0, 0, 0], qc.Vehicle(drag=(0.2, 0.2, 0.2)))
    Traceback (most recent call last):
    ...
    quadctl.errors.TrimError: no equilibrium at velocity_ned [0, 0, -10] m/s: it needs thrust ... <= 0 ...
    """

    from_config = True


class LogError(QuadctlError, ValueError):
    """A flight log cannot be read (truncated, corrupted, a column missing) or cannot support the
    identification asked of it (no excitation, saturated motors, a dropped sensor): the message
    names the file and the fix."""


class CheckFailed(QuadctlError):
    """The input is valid but the design fails a check (rank, stability, divergence)."""

    exit_code = 1


class DesignError(CheckFailed, ValueError):
    """A subsystem is not stabilizable, or a Riccati solve failed.

    Examples
    --------
    >>> import quadctl as qc
    >>> qc.lqr([[1.0]], [[0.0]], [[1.0]], [[1.0]])  # an unstable mode no input reaches
    Traceback (most recent call last):
    ...
    quadctl.errors.DesignError: ...
    """

    from_config = True


class ImplausibleConfig(CheckFailed, ValueError):
    """The config's values look like a unit slip (see :mod:`quadctl.config.notices`), and the config does
    not accept it (``allow: [implausible]``)."""


class SaturationFailed(CheckFailed):
    """The simulated design sits at an actuator limit most of the run, and the config or command
    line does not accept it (``allow: [saturation]``, ``--allow-saturation``)."""

    from_config = True


class StepSizeError(QuadctlError, ValueError):
    """A fixed step that RK4 cannot hold stable for the closed loop."""

    from_config = True


class QuadctlNotice(UserWarning):
    """Something the user should know that does not stop the run (a fallback, a default taken).

    The library issues it with :func:`warnings.warn`; the CLI prints it as one ``notice`` line.
    """
