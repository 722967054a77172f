"""python-control interop: quadctl's models and designs as ``control.StateSpace``, and back.

:func:`plant`, :func:`subsystem`, :func:`controller` (the LQG compensator too) and
:func:`closed_loop` carry quadctl's own matrices with named signals, continuous or at the design's
``dt``; :func:`from_statespace` makes a ``StateSpace`` a :class:`Plant` quadctl designs for.
python-control (``pip install '.[control]'``) is imported on first use. See docs/guide/export.md
("python-control").

Examples
--------
>>> from quadctl import config, pipeline
>>> from quadctl.export import interop
>>> from quadctl.setup import setup_of
>>> setup = setup_of(config.load("crazyflie"))
>>> linear = pipeline.linear_of(setup, pipeline.trim_of(setup))
>>> sys = interop.plant(linear)
>>> sys.state_labels[:3], sys.input_labels
(['pN', 'pE', 'pD'], ['T', 'A', 'E', 'R'])
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from quadctl.design import discrete, integral, linear_loop, lqr
from quadctl.design.riccati import real_array
from quadctl.errors import ArgumentError, ArgumentTypeError
from quadctl.layout import INPUT_NAMES, STATE_INDEX, STATE_NAMES
from quadctl.linear.filters import RATE_STATES, series

INSTALL_HINT = "pip install '.[control]' (in a quadctl checkout) or pip install 'quadctl[control]'"


def _control():
    """The python-control module, or an ImportError that says how to install it."""
    try:
        import control
    except ModuleNotFoundError:
        raise ModuleNotFoundError(f"quadctl.export.interop needs python-control: {INSTALL_HINT}",
                                  name="control") from None
    return control


def plant(linear, *, sample_time: float | None = None, name: str = "plant"):
    """The linearization ``dx' = A dx + B du`` as a StateSpace whose outputs are the states.

    Parameters
    ----------
    linear : quadctl.linear.linearize.LinearModel
        ``A`` (12, 12) and ``B`` (12, 4) about the trim.
    sample_time : float, optional
        s. Given: the zero-order-hold plant (:func:`quadctl.design.discrete.c2d`) with ``dt = sample_time``.
    name : str

    Returns
    -------
    control.StateSpace
        States and outputs named ``pN ... r``, inputs ``T A E R`` (deviations from the trim).

    Raises
    ------
    ArgumentTypeError
        ``linear`` has no ``A`` and ``B`` (``stages.linear`` is the model; a ``TypeError``).
    ArgumentError
        ``A``, ``B`` not real (12, 12) and (12, 4), or ``sample_time`` not a positive number of seconds.
    """

    _control()
    _require(linear, ("A", "B"), "plant", "linear", "a quadctl.linear.linearize.LinearModel, stages.linear")
    A, B = _held(linear.A, linear.B, sample_time, "plant")
    A = real_array(A, "linear.A", name="plant", error=ArgumentError, shape=(len(STATE_NAMES), len(STATE_NAMES)))
    B = real_array(B, "linear.B", name="plant", error=ArgumentError, shape=(len(STATE_NAMES), len(INPUT_NAMES)))
    return _ss(A, B, STATE_NAMES, INPUT_NAMES, STATE_NAMES, sample_time, name)


def subsystem(sub, *, sample_time: float | None = None):
    """A decoupled subsystem (:class:`quadctl.linear.decouple.Subsystem`) as a StateSpace.

    Its outputs are its measured states (the rows of ``sub.C``); with ``sample_time`` the
    zero-order-hold discretization.

    Raises
    ------
    ArgumentTypeError
        ``sub`` is not a subsystem (``stages.decoupled["pitch"]``; a ``TypeError``).
    ArgumentError
        Its matrices are not real or do not fit its states and inputs, or ``sample_time`` is not a
        positive number of seconds.
    """
    _control()
    _require(sub, ("A", "B", "C", "states", "inputs", "name"), "subsystem", "sub",
             "a quadctl.linear.decouple.Subsystem, stages.decoupled['pitch']")

    A, B = _held(sub.A, sub.B, sample_time, "subsystem")
    C = real_array(sub.C, "sub.C", name="subsystem", error=ArgumentError, ndim=2, shape=(None, A.shape[0]))
    if A.shape[0] != len(sub.states) or B.shape[1] != len(sub.inputs):
        raise ArgumentError(f"subsystem: A is {A.shape[0]} x {A.shape[0]} and B has {B.shape[1]} columns for "
                            f"{len(sub.states)} states and {len(sub.inputs)} inputs")
    outputs = [sub.states[int(np.argmax(np.abs(row)))] for row in C]
    return _ss(A, B, sub.states, sub.inputs, outputs, sample_time, sub.name, C=C)


def controller(design, *, sample_time: float | str | None = "design", name: str = "controller"):
    """The controller of a design: measured state deviations in, input deviations out.

    ``u = -K x - Ki z`` with ``dz/dt = -C x`` (continuous) or ``z[k+1] = z[k] - Ts C x[k]``
    (sampled, as :mod:`quadctl.sim.builder` runs it), ``C`` selecting the integrated states.

    Parameters
    ----------
    design : quadctl.design.Design or quadctl.sim.loop.ClosedLoop
        Anything with ``K`` or ``K_block`` (4, 12), ``Ki``/``Ki_block`` (4, nz), ``integral_states``.
    sample_time : float, None or "design"
        s; ``"design"``: the design's own (a discrete design's, else continuous).
    name : str

    Returns
    -------
    control.StateSpace
        States ``z_<state>``, inputs the 12 state names, outputs ``T A E R``. A
        :class:`~quadctl.sim.loop.ClosedLoop` with a Kalman filter gives the LQG compensator
        (:func:`_lqg_controller`): states ``xh_<state>`` then ``z_<state>``, the unmeasured inputs
        unused, at the filter's sample time.

    Raises
    ------
    ArgumentError
        The design includes the rotors' lag, or an LQG loop has a delay (the filter's command
        buffer) or is asked for another sample time than its filter's.
    """

    _control()
    K, Ki, ints = _gains(design)
    if getattr(design, "estimator", None) is not None:
        return _lqg_controller(design, K, Ki, ints, sample_time, name)
    Ts = getattr(design, "sample_time", None) if sample_time == "design" else _sample_time(sample_time, "controller")
    C = integral.selector(STATE_NAMES, ints)
    nz = len(ints)
    A = np.eye(nz) if Ts else np.zeros((nz, nz))
    B = -(Ts or 1.0) * C
    rate_filter = getattr(design, "rate_filter", None)
    if rate_filter is not None:  # the law's gyro filter: its states after the integrators'
        return _filtered_controller(A, B, K, Ki, ints, rate_filter.form(Ts), Ts, name)
    return _ss(A, B, [f"z_{s}" for s in ints], STATE_NAMES, INPUT_NAMES, Ts, name, C=-Ki, D=-K)


def _filtered_controller(A, B, K, Ki, ints, form, Ts, name):
    """The controller of a loop whose law takes the body rates through its gyro filter ``form``
    (:func:`quadctl.linear.filters.with_rate_filter`): states ``[z; g]`` (``g_<rate>_<i>``, ``form.order``
    per rate), ``g' = A_f g + b_f r`` (or ``g+``), ``u = -K' x - K_r c_f g - Ki z`` with ``K'`` the gain whose
    rate columns are ``d_f K_r``."""

    nz, k = len(ints), form.order
    ng = k * len(RATE_STATES)
    Aa = np.zeros((nz + ng, nz + ng))
    Aa[:nz, :nz] = A
    Ba = np.vstack([B, np.zeros((ng, len(STATE_NAMES)))])
    Cg = np.zeros((K.shape[0], ng))
    D = -K.copy()
    names = [f"z_{s}" for s in ints]
    for j, rate in enumerate(RATE_STATES):
        i, g = STATE_INDEX[rate], slice(nz + j * k, nz + (j + 1) * k)
        Aa[g, g] = form.A
        Ba[g, i] = form.b
        Cg[:, j * k:(j + 1) * k] = -np.outer(K[:, i], form.c)
        D[:, i] *= form.d
        names += [f"g_{rate}_{m}" for m in range(k)]
    return _ss(Aa, Ba, names, STATE_NAMES, INPUT_NAMES, Ts, name, C=np.hstack([-Ki, Cg]), D=D)


def _lqg_controller(loop, K, Ki, ints, sample_time, name):
    """The LQG compensator of a loop through a Kalman filter (:func:`controller` of an LQG loop).

    Inputs the 12 state deviations (only the measured ones enter, ``y = C dx``), states
    ``[xh_<state>; z_<state>]``, outputs ``T A E R``, as :mod:`quadctl.sim.builder` runs it without
    saturation. Discrete filter form (``M``): ``xc = (I - M C) xh + M y``, ``u = -K xc - Ki z``,
    ``xh+ = Ae xc + Be u``, ``z+ = z - Ts S xc``. Kalman-Bucy (``L``): ``u = -K xh - Ki z``,
    ``xh' = Ae xh + Be u + L (y - C xh)``, ``z' = -S xh``. ``S`` selects the integrated states.

    With the gyro filter in the Kalman filter's model (``controller.filters``) the compensator runs the
    gyro filter too, as the flight computer does: states ``[g_<rate>_<i>; xh_<state>; xh_g_<rate>_<i>;
    z_<state>]``, ``g`` the filter on the raw rates (``g+ = A_f g + b_f r``, or ``g'``), ``y = C [dx; g]``
    (a measured rate read filtered), ``K`` acting on the estimate of ``dx``.
    """

    kal = loop.estimator
    Ts = kal.sample_time
    if sample_time != "design" and (sample_time or None) != Ts:
        raise ArgumentError(f"controller: sample_time = {sample_time}: an LQG controller runs at its Kalman filter's "
                            f"{'sample time ' + format(Ts, 'g') + ' s' if Ts else 'continuous time'}; "
                            "leave sample_time at 'design'")
    if getattr(loop, "delay_samples", 0):
        raise ArgumentError("controller: the loop's Kalman filter predicts with the command of controller.delay "
                            "samples ago: its buffer is not in these python-control systems; export it with quadctl "
                            "export (C carries it), or remove controller.delay")
    Ae, Be, Ca = (np.asarray(M, dtype=float) for M in (kal.A, kal.B, kal.C))
    gain, n, nz, ne = np.asarray(kal.gain, dtype=float), len(STATE_NAMES), len(ints), kal.n_estimate
    ng = ne - n
    C, Cg = Ca[:, :n], Ca[:, n:]  # y = C dx + Cg g
    S = np.hstack([integral.selector(STATE_NAMES, ints), np.zeros((nz, ng))])
    Ke = np.hstack([K, np.zeros((K.shape[0], ng))])  # the law on the estimate of dx
    AeK = linear_loop.close(Ae, Be, Ke)  # the estimate's loop under the law
    form = kal.rate_filter.form(Ts) if kal.rate_filter is not None else None
    rows = series(np.zeros((n, n)), np.zeros((n, 1)), form, [STATE_INDEX[r] for r in RATE_STATES])[0][n:]
    Ag, Bg = rows[:, n:], rows[:, :n]  # g' (or g+) = Ag g + Bg dx
    Z = np.zeros
    if Ts:
        F = np.eye(ne) - gain @ Ca  # xc = F xh + M C dx + M Cg g
        Nx, Ng = gain @ C, gain @ Cg
        A = np.block([[Ag, Z((ng, ne)), Z((ng, nz))],
                      [AeK @ Ng, AeK @ F, -Be @ Ki],
                      [-Ts * S @ Ng, -Ts * S @ F, np.eye(nz)]])
        B = np.vstack([Bg, AeK @ Nx, -Ts * S @ Nx])
        Cout, D = np.hstack([-Ke @ Ng, -Ke @ F, -Ki]), -Ke @ Nx
    else:
        A = np.block([[Ag, Z((ng, ne)), Z((ng, nz))],
                      [gain @ Cg, AeK - gain @ Ca, -Be @ Ki],
                      [Z((nz, ng)), -S, Z((nz, nz))]])
        B = np.vstack([Bg, gain @ C, Z((nz, n))])
        Cout, D = np.hstack([Z((K.shape[0], ng)), -Ke, -Ki]), Z((K.shape[0], n))
    gyro = list(kal.state_names[n:])
    states = [*gyro, *(f"xh_{s}" for s in kal.state_names), *(f"z_{s}" for s in ints)]
    return _ss(A, B, states, STATE_NAMES, INPUT_NAMES, Ts, name, C=Cout, D=D)


def closed_loop(linear, design, *, sample_time: float | str | None = "design", name: str = "closed loop"):
    """The linear closed loop of ``[x; z]`` (:func:`quadctl.design.linear_loop.matrix`) as a StateSpace.

    Its inputs are disturbances ``T A E R`` added to the controller's input (``B``, or the hold's
    ``Bd`` when sampled), its outputs the loop states.

    Parameters
    ----------
    linear : quadctl.linear.linearize.LinearModel
    design : quadctl.design.Design or quadctl.sim.loop.ClosedLoop
    sample_time : float, None or "design"
        s; ``"design"``: the design's own.
    name : str

    Returns
    -------
    control.StateSpace
        Its poles are the closed-loop eigenvalues (``z`` when sampled).
    """

    _control()
    K, Ki, ints = _gains(design)
    if getattr(design, "rate_filter", None) is not None:
        raise ArgumentError("closed_loop: the law takes the body rates through its gyro filter (controller.filters): "
                            "closed_loop is the loop of [x; z]; for the loop with the filter use control.feedback("
                            "interop.plant(linear, sample_time=Ts), interop.controller(loop), sign=1)")
    if getattr(design, "estimator", None) is not None:
        raise ArgumentError("closed_loop: the loop closes through a Kalman filter (estimator:): closed_loop is the "
                            "full-state loop of [x; z]; for the LQG loop use control.feedback(interop.plant(linear, "
                            "sample_time=Ts), interop.controller(loop), sign=1)")
    Ts = getattr(design, "sample_time", None) if sample_time == "design" else _sample_time(sample_time, "closed_loop")
    _require(linear, ("A", "B"), "closed_loop", "linear", "a quadctl.linear.linearize.LinearModel, stages.linear")
    A, B = _held(linear.A, linear.B, None, "closed_loop")
    n, m = len(STATE_NAMES), len(INPUT_NAMES)
    A = real_array(A, "linear.A", name="closed_loop", error=ArgumentError, shape=(n, n))
    B = real_array(B, "linear.B", name="closed_loop", error=ArgumentError, shape=(n, m))
    A_cl = linear_loop.matrix(A, B, K, Ki, ints, Ts)
    B = B if not Ts else discrete.c2d(A, B, Ts)[1]
    B_cl = np.vstack([B, np.zeros((len(ints), B.shape[1]))])
    names = [*STATE_NAMES, *(f"z_{s}" for s in ints)]
    return _ss(A_cl, B_cl, names, INPUT_NAMES, names, Ts, name)


@dataclass(frozen=True)
class Plant:
    """A linear plant from python-control, checked, for quadctl to design for.

    Unpacks like :class:`quadctl.linear.linearize.LinearModel`: ``A, B = plant``.

    Attributes
    ----------
    A : (n, n) ndarray
    B : (n, m) ndarray
    state_names : tuple of str
    input_names : tuple of str
    dt : float
        0 for a continuous plant, else the sample time (s).
    """

    A: np.ndarray
    B: np.ndarray
    state_names: tuple[str, ...]
    input_names: tuple[str, ...]
    dt: float = 0.0

    def __iter__(self):
        return iter((self.A, self.B))

    def lqr(self, Q, R, N=None):
        """``K, P, E``: :func:`quadctl.design.lqr` for a continuous plant, :func:`quadctl.design.discrete.dlqr`
        for a discrete one (decided by ``dt``, as python-control's ``lqr(sys, Q, R, N)`` does); ``N`` the
        cross weight."""

        if self.dt:
            return discrete.dlqr(self.A, self.B, Q, R, N, name="plant", state_names=self.state_names)
        return lqr(self.A, self.B, Q, R, N, name="plant", state_names=self.state_names)


def from_statespace(sys) -> Plant:
    """A python-control ``StateSpace`` (its ``A``, ``B``, signal names and ``dt``) as a :class:`Plant`.

    Parameters
    ----------
    sys : control.StateSpace

    Returns
    -------
    Plant

    Raises
    ------
    ArgumentTypeError
        Not a state-space system (a ``TransferFunction``: convert it with ``control.ss``).
    ArgumentError
        No states, non-finite entries, or an unspecified timebase (``dt = None`` or ``True``: give the
        sample time).
    """
    if not all(hasattr(sys, attr) for attr in ("A", "B", "state_labels", "input_labels")):
        raise ArgumentTypeError(f"from_statespace: expected a control.StateSpace, got {type(sys).__name__}; "
                                "convert it with control.ss(sys)")

    A = real_array(sys.A, "sys.A", name="from_statespace", error=ArgumentError, ndim=2)
    B = real_array(sys.B, "sys.B", name="from_statespace", error=ArgumentError, ndim=2)
    n = A.shape[0]
    if n == 0:
        raise ArgumentError("from_statespace: the system has no states: nothing to regulate")
    for label, M in (("A", A), ("B", B)):
        if not np.all(np.isfinite(M)):
            raise ArgumentError(f"from_statespace: sys.{label} has non-finite entries; a plant to design for needs "
                                "finite matrices")
    if A.shape != (n, n) or B.shape[0] != n:
        raise ArgumentError(f"from_statespace: sys.A has shape {A.shape} and sys.B {B.shape}: expected (n, n) and "
                            "(n, m)")
    dt = sys.dt
    if dt is None or dt is True:
        raise ArgumentError(f"from_statespace: the system's timebase is unspecified (dt = {dt}); give dt = 0 "
                            "(continuous) or the sample time in s")
    return Plant(A=A, B=B, state_names=tuple(sys.state_labels), input_names=tuple(sys.input_labels),
                 dt=float(dt))


def _gains(design):
    if getattr(design, "lag_time_constant", None) is not None or getattr(design, "Kv", None) is not None:
        raise ArgumentError("interop: the design includes the rotors' lag (controller.rotor_lag: include): its "
                            "controller has lag-model states these python-control systems do not carry; export it "
                            "with quadctl export (C, .mat or JSON: Kv and the law), or design with rotor_lag: ignore")

    label = "K_block" if hasattr(design, "K_block") else "K"
    if not hasattr(design, label) or not hasattr(design, "integral_states"):
        raise ArgumentTypeError(f"design must be a quadctl.design.Design or a quadctl.sim.loop.ClosedLoop (K or "
                                f"K_block, integral_states), got {type(design).__name__}")
    n, m = len(STATE_NAMES), len(INPUT_NAMES)
    K = real_array(getattr(design, label), f"design.{label}", name="interop", error=ArgumentError, shape=(m, n))
    ints = tuple(design.integral_states)
    unknown = [s for s in ints if s not in STATE_NAMES]
    if unknown:
        raise ArgumentError(f"interop: design.integral_states names {unknown[0]!r}, not a state "
                            f"({' '.join(STATE_NAMES)})")
    ki_label = "Ki_block" if hasattr(design, "Ki_block") else "Ki"
    Ki = getattr(design, ki_label, None)
    if Ki is None or not ints:
        return K, np.zeros((m, 0)), ints
    Ki = real_array(Ki, f"design.{ki_label}", name="interop", error=ArgumentError, ndim=2, shape=(m, len(ints)))
    return K, Ki, ints


def _require(obj, attrs: tuple, who: str, label: str, what: str) -> None:
    """An ArgumentTypeError naming what ``label`` takes when ``obj`` lacks one of ``attrs`` (an AttributeError
    from inside, otherwise)."""
    if not all(hasattr(obj, a) for a in attrs):
        raise ArgumentTypeError(f"{who}: {label} must be {what}; got {type(obj).__name__}")


def _held(A, B, sample_time, who: str = "interop"):
    """``(A, B)`` checked (real, ``A`` n x n, ``B`` n x m), or with a sample time the zero-order-hold
    plant ``(Ad, Bd)``."""

    A = real_array(A, "A", name=who, error=ArgumentError, ndim=2)
    A = real_array(A, "A", name=who, error=ArgumentError, shape=(A.shape[0], A.shape[0]))
    B = real_array(B, "B", name=who, error=ArgumentError, ndim=2, shape=(A.shape[0], None))
    return discrete.c2d(A, B, _sample_time(sample_time, who)) if sample_time else (A, B)


def _sample_time(sample_time, who: str):
    """A sample time argument: None or 0 (continuous), else a positive finite number of seconds."""
    if sample_time is None or sample_time == 0:
        return None
    if isinstance(sample_time, bool) or not isinstance(sample_time, (int, float, np.integer, np.floating)) \
            or not np.isfinite(sample_time) or sample_time < 0:
        raise ArgumentError(f"{who}: sample_time = {sample_time!r}: must be a positive finite number of seconds, "
                            "or None for continuous time")
    return float(sample_time)


def _ss(A, B, states, inputs, outputs, sample_time, name, C=None, D=None):
    """A StateSpace with named signals (``C`` default identity, ``D`` zero), ``dt = sample_time or 0``."""
    control = _control()
    A, B = np.asarray(A, dtype=float), np.asarray(B, dtype=float)
    n, m = A.shape[0], B.shape[1]
    C = np.eye(n) if C is None else np.asarray(C, dtype=float)
    D = np.zeros((C.shape[0], m)) if D is None else np.asarray(D, dtype=float)
    return control.ss(A, B, C, D, sample_time or 0, states=list(states), inputs=list(inputs),
                      outputs=list(outputs), name=name)
