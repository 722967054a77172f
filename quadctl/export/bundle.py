"""The :class:`Export`: a design ready to leave quadctl, and its control law in words.

What every writer (:mod:`quadctl.export.c`, :mod:`quadctl.export.data`) reads; built by
:func:`quadctl.export.prepare`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from quadctl.design import Design, linear_loop
from quadctl.design.gain_table import VARIABLES
from quadctl.errors import ArgumentTypeError
from quadctl.linear.decouple import Decoupled
from quadctl.linear.linearize import LinearModel
from quadctl.setup import Setup
from quadctl.sim.loop import ClosedLoop

if TYPE_CHECKING:
    from quadctl.schedule.envelope import Schedule


@dataclass(frozen=True)
class Export:
    """A design ready to leave quadctl.

    Attributes
    ----------
    setup : Setup
        The resolved config (its timing is the exported one: a continuous design exported at
        ``--rate`` has ``timing.mode == "emulated"``).
    linear : LinearModel
        The linearization at the trim (continuous ``A``, ``B``).
    decoupled : Decoupled
    design : Design
    loop : ClosedLoop
        The loop as ``quadctl simulate`` runs it (gains, trim, reference drift, integrators, actuators).
    rate_warnings : tuple of quadctl.design.discrete.RateWarning
        Loops of a continuous design that the rate realizes only approximately (still stable).
    config_hash : str or None
        sha256 of the config (:meth:`quadctl.config.Config.digest`): the provenance the files carry.
    schedule : quadctl.schedule.envelope.Schedule or None
        The gain schedule whose table ``loop`` flies (``schedule:``; its values with no trim are left
        out of the table); None without one.
    """

    setup: Setup
    linear: LinearModel
    decoupled: Decoupled
    design: Design
    loop: ClosedLoop
    rate_warnings: tuple = ()
    config_hash: str | None = None
    schedule: Schedule | None = None

    @property
    def name(self) -> str:
        return self.setup.name

    @property
    def rate(self) -> float | None:
        """Hz the controller runs at (None: continuous feedback, a ``.mat``/JSON export only)."""
        return self.setup.timing.rate

    @property
    def sample_time(self) -> float | None:
        """s between controller samples (None: continuous)."""
        return self.setup.timing.sample_time

    @property
    def mode(self) -> str:
        """``discrete`` (designed at the rate), ``emulated`` (continuous design sampled) or ``continuous``."""
        return self.setup.timing.mode

    def closed_loop_matrix(self) -> np.ndarray:
        """The linear closed loop of ``[x; z]`` as exported: ``z``-domain when sampled (ZOH plant).
        A design that includes the rotors' lag: of ``[x; v; z]`` (the lag states as the design sees
        them; the controller's lag model equals them while the model is right)."""
        return linear_loop.matrix(self.linear.A, self.linear.B, self.loop.K, self.loop.Ki,
                                  self.loop.integral_states, self.sample_time, Kv=self.loop.Kv,
                                  lag_time_constant=self.loop.lag_model_time_constant)

    def closed_loop_eigenvalues(self) -> np.ndarray:
        """Eigenvalues of :meth:`closed_loop_matrix` (``z`` when sampled, ``s`` in rad/s when continuous)."""
        return np.linalg.eigvals(self.closed_loop_matrix())

    @property
    def flies_reference(self) -> bool:
        """The loop flies a reference (``simulation.reference``): ``x_ref`` and ``u_ref`` are inputs of
        the law at each sample (:data:`quadctl.sim.loop_layout.REFERENCE_LAYOUT`), not the trim."""
        return self.setup.reference is not None

    def law(self) -> str:
        """The control law in words and symbols, with this loop's timing, integrators and saturation."""
        return law_text(self.loop, self.sample_time, reference=self.flies_reference)



def require_export(exp, who: str) -> Export:
    """``exp``, checked to be an :class:`Export` (what :func:`quadctl.export.prepare` returns); an
    :class:`~quadctl.errors.ArgumentTypeError` (a ``TypeError``) naming ``who`` and what was given otherwise.

    >>> require_export(None, "sources")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    quadctl.errors.ArgumentTypeError: sources: exp must be a quadctl.export.Export (from ...), got NoneType
    """
    if not isinstance(exp, Export):
        raise ArgumentTypeError(f"{who}: exp must be a quadctl.export.Export (from quadctl.export.prepare), "
                                f"got {type(exp).__name__}")
    return exp


def law_text(loop: ClosedLoop, sample_time: float | None, reference: bool = False,
             source: str = "simulation.reference",
             feedforward: str = "the differential-flatness trim along the path") -> str:
    """The control law of ``loop`` in one paragraph (the C header, the ``.mat`` and the JSON say it);
    ``reference``: the loop flies a reference, ``x_ref(t)`` and ``u_ref(t)`` given, not the trim, from
    ``source``, its feedforward ``feedforward`` (the Crazyflie app's: the commander's setpoints, the hover trim's).

    Examples
    --------
    >>> from quadctl.sim.loop import ClosedLoop
    >>> z = np.zeros(12)
    >>> for part in law_text(ClosedLoop(z, z, np.zeros(4), z, np.zeros((4, 12)), z), None).split("; "):
    ...     print(part)
    u = u_trim - K (x - x_ref(t)), x_ref(t) = x_trim + x_rate t
    the yaw error wrapped into (-pi, pi]
    continuous feedback
    no input limits.
    """
    ints, act = loop.integral_states, loop.actuators
    u_ref = "u_ref(t)" if reference else "u_trim"
    inner = f"{u_ref} - K (x - x_ref(t))" + (" - Ki z" if ints else "") + (" - Kv l" if loop.Kv is not None else "")
    parts = [(f"u = {inner}" if act is None else f"u = sat({inner})")
             + (f", x_ref(t) and u_ref(t) the reference flown ({source}): the commanded state and its "
                f"feedforward input ({feedforward}); x - x_ref(t) is taken in the "
                "reference's heading frame, its pN, pE turned by -(psi_ref(t) - psi_d), psi_d the yaw the gain was "
                "designed at (the trim's" + (", or a yaw schedule's value held to its ends" if loop.schedule is not None
                                              and loop.schedule.variable == "yaw" else "")
                + "), so the design holds at any heading" if reference
                else ", x_ref(t) = x_trim + x_rate t") + "; the yaw error wrapped into (-pi, pi]"]
    table = loop.schedule
    if table is not None:

        gains = "K and Ki" if ints and table.coefficients.shape[-1] > len(loop.x_trim) else "K"
        parts.append(f"{gains} = G(v), the gain schedule on {table.variable} v ({VARIABLES[table.variable]}) of "
                     f"x_ref(t): the designs at v = {', '.join(f'{v:g}' for v in table.values)}, "
                     f"{table.interpolation} between them, held outside them")
    if sample_time is None:
        parts.append("continuous feedback")
    else:
        parts.append(f"sampled every Ts = {sample_time:.9g} s at t = k Ts (k counts the samples) and held "
                     "until the next (zero-order hold)")
    if ints:
        step = "z <- z - Ts (x_i - x_ref_i(t))" if sample_time is not None else "dz/dt = -(x_i - x_ref_i(t))"
        parts.append(f"{step} for i = {', '.join(ints)} (MATLAB lqi), frozen while saturation changes an input "
                     "that its Ki drives (conditional integration)")
    if loop.Kv is not None:
        tau = loop.lag_model_time_constant
        step = ("l <- a l + (1 - a) (u - u_trim), a = exp(-Ts / tau)" if sample_time is not None
                else "dl/dt = (u - u_trim - l) / tau")
        parts.append(f"{step}, tau = {tau:g} s: the controller's model l of the rotors' lag (the deviation of "
                     "[T, A, E, R] from trim), driven by its own command u, starting at 0")
    filt = getattr(loop, "rate_filter", None)
    if filt is not None:
        step = "g <- A g + b r" if sample_time is not None else "dg/dt = A g + b r"
        parts.append(f"the rates p, q, r in x are the gyro's through its filter ({filt.describe()}): y = c g + d r, "
                     f"{step} on each measured rate r, g starting at 0")
    kal = loop.estimator
    if kal is not None:
        y = f"y = the measured {', '.join(kal.measured)}"
        if kal.form == "filter":
            parts.append(f"x - x_ref(t) is the Kalman filter's estimate xc = xh + M (y - C x_ref(t) - C xh) ({y}; M "
                         f"the filter gain of dlqe), then xh <- Ae xc + Be (u - {u_ref}) with the applied u "
                         "(xh the a priori estimate, starting at 0)")
        else:
            parts.append(f"x - x_ref(t) is the Kalman-Bucy filter's estimate xh, dxh/dt = Ae xh + Be (u - {u_ref}) "
                         f"+ L (y - C x_ref(t) - C xh) ({y}), starting at 0")
    if loop.delay_samples and sample_time is not None:
        n = loop.delay_samples
        parts.append(f"the vehicle applies u {n} sample{'s' if n > 1 else ''} ({n * sample_time:.6g} s, "
                     "controller.delay) after computing it: the delay is the vehicle's, not part of this law")
    if act is None:
        parts.append("no input limits")
    elif act.mode == "motors":
        m = act.motors
        rotors = (f"four rotors ({m.describe()}, {m.torque_coefficient:g} N m of yaw torque per N, each within "
                  f"[{m.min_thrust:g}, {m.max_thrust:g}] N)")
        if act.priority:
            parts.append(f"sat: by priority on the {rotors}: the roll and pitch torques kept (scaled together when "
                         "no thrust fits them), then the thrust, the yaw torque given up first")
        else:
            parts.append(f"sat: the command mixed to the {rotors}, each clipped, mixed back")
    else:
        limited = [f"{n} in [{lo:g}, {hi:g}]" for n, lo, hi in zip(act.names, act.lo, act.hi)
                   if np.isfinite(lo) or np.isfinite(hi)]
        parts.append("sat: each input clipped to its limits (" + ", ".join(limited) + ")")
    return "; ".join(parts) + "."
