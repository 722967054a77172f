"""The one closed-loop definition: CasADi functions of one step (RK4, or ETDRK4) of plant and controller.

Every runner is generated from what this module builds: the compiled one-case loop and the SIMD
lanes (emitted as C by :mod:`quadctl.native.emit`) and the interpreted fallback
(:mod:`quadctl.sim.interpreted`). The plant is :func:`quadctl.physics.model.build_model`; a loop's structure
is a :class:`~quadctl.sim.loop_spec.LoopSpec`, its numbers one constant vector
(:func:`~quadctl.sim.loop_layout.constant_layout`), its per-step inputs an exogenous row
(:func:`~quadctl.sim.loop_layout.exo_layout`), of :mod:`quadctl.sim.loop_spec` and :mod:`quadctl.sim.loop_layout`.
The loop's state, law, timings and features are described in the docs, docs/internals.md ("The closed loop").
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from quadctl._lazy import lazy_import
from quadctl.design.gain_table import scheduling_value
from quadctl.layout import GRAVITY, N_INPUTS, N_STATES, PRODUCTS, STATE_INDEX
from quadctl.physics.model import N_DISTURBANCES, N_WIND, build_model
from quadctl.physics.motors import desaturate
from quadctl.physics.reference_rows import ROW_HALF
from quadctl.sim import pid
from quadctl.sim.loop_layout import N_EXO, N_RATES, N_REFERENCE, PHI_LAYOUT, constant_layout
from quadctl.sim.loop_spec import LoopSpec

ca = lazy_import("casadi")  # loaded on first use: see quadctl._lazy

ANTIWINDUP_TOL = 1e-10
"""An input counts as saturated when clipping changed it by more than this (N or N m): far above
the round-off of mixing and unmixing (~1e-15), far below any clip that matters."""

_PN, _PE, _PSI, _P = STATE_INDEX["pN"], STATE_INDEX["pE"], STATE_INDEX["psi"], STATE_INDEX["p"]


def wrap_angle(angle, lib=np):
    """``angle`` (rad) wrapped into ``(-pi, pi]``: ``angle + 2 pi floor((pi - angle) / (2 pi))``, so
    an angle already there is returned bit for bit (``+ 0``), however many turns it is off. (The
    division is a product by ``0.5 / pi``: the floor sits on the law's path in every RK4 stage, and a
    divide there is a visible part of a continuous loop's step.)

    >>> float(wrap_angle(-np.pi)), float(wrap_angle(np.pi)), float(wrap_angle(0.25 + 6 * np.pi))
    (3.141592653589793, 3.141592653589793, 0.25)
    """
    return angle + 2 * np.pi * lib.floor((np.pi - angle) * (0.5 / np.pi))


def heading_frame(dx, offset, lib=ca):
    """The deviation ``dx = x - x_ref`` (12,) as the law takes it: its ``pN, pE`` rotated into the
    reference's heading frame, ``offset`` (rad) the reference's yaw less the design's, and its
    ``psi`` wrapped into ``(-pi, pi]`` (:func:`wrap_angle`).

    The heading is a symmetry of the model: turning the vehicle and its reference by ``a`` about the
    vertical leaves the body velocities ``u, v, w``, the roll, pitch and rates unchanged and turns the
    horizontal position by ``a``, so ``R(-a) [dpN, dpE]`` is the position error the design saw at its
    own heading. At ``offset = 0`` every entry is ``dx``'s, bit for bit (``1 e + 0 e'``).

    Parameters
    ----------
    dx : (12,) CasADi column, or (..., 12) ndarray with ``lib=numpy``
    offset : CasADi scalar, or float or (...,) ndarray
    lib : module
        ``casadi`` or ``numpy``.
    """
    if lib is np:
        out = np.array(dx, dtype=float, copy=True)
        c, s = np.cos(offset), np.sin(offset)
        out[..., _PN] = c * dx[..., _PN] + s * dx[..., _PE]
        out[..., _PE] = c * dx[..., _PE] - s * dx[..., _PN]
        out[..., _PSI] = wrap_angle(out[..., _PSI])
        return out
    c, s = ca.cos(offset), ca.sin(offset)
    north = c * dx[_PN] + s * dx[_PE]
    east = c * dx[_PE] - s * dx[_PN]
    return ca.vertcat(north, east, dx[_PN + 2:_PSI], wrap_angle(dx[_PSI], ca), dx[_PSI + 1:])


def scheduled_gain(v, breaks, coefficients, pieces: int, mask: np.ndarray, degree: int = 3):
    """The table's gain ``G(v)`` (4, m) as CasADi expressions of the scheduling value ``v``.

    ``v`` is held to ``[breaks[0], breaks[pieces]]``; the piece ``i`` with ``breaks[i] <= v <
    breaks[i + 1]`` (the last piece also at its end, as :meth:`quadctl.design.gain_table.GainTable.at`)
    is chosen by a sum over pieces of ``if_else(indicator, coefficient, 0)``, exactly one term
    nonzero, so the selected coefficients are the table's, bit for bit; then Horner's rule in
    ``s = v - breaks[i]``. Only comparisons, ``if_else``, ``fmin``/``fmax`` and arithmetic: every
    runner (the emitted C of one case and of the lanes, CasADi's virtual machine) takes it alike.

    Parameters
    ----------
    v : CasADi scalar
        The scheduling value (:func:`quadctl.design.gain_table.scheduling_value`).
    breaks : CasADi column (pieces + 1,)
    coefficients : CasADi column
        The (4, pieces, 4, m) coefficients, column-major.
    pieces : int
    mask : (4, m) ndarray of bool
        Entries that may be nonzero; the others are structural zeros of the result.
    degree : int
        The highest power of ``s`` read (the table's higher coefficients are all zero): Horner's rule
        from there gives the bits of the full cubic's (``(0 s + 0) s + c = c``) for less work.
    """
    m = mask.shape[1]
    vc = ca.fmin(ca.fmax(v, breaks[0]), breaks[pieces])
    inside = []
    for i in range(pieces):
        lower = vc >= breaks[i] if i else None
        upper = vc < breaks[i + 1] if i < pieces - 1 else None
        inside.append(upper if lower is None else (lower if upper is None else ca.logic_and(lower, upper)))

    def select(values):
        if pieces == 1:
            return values[0]
        out = ca.if_else(inside[0], values[0], 0)
        for i in range(1, pieces):
            out = out + ca.if_else(inside[i], values[i], 0)
        return out

    s = vc - select([breaks[i] for i in range(pieces)])
    G = ca.SX(N_INPUTS, m)
    for col in range(m):
        for r in range(N_INPUTS):
            if not mask[r, col]:
                continue
            coef = [select([coefficients[k + 4 * (i + pieces * (r + N_INPUTS * col))] for i in range(pieces)])
                    for k in range(3 - degree, 4)]
            value = coef[0]
            for c in coef[1:]:
                value = value * s + c
            G[r, col] = value
    return G


@dataclass(frozen=True)
class LoopFunctions:
    """The CasADi functions of one spec (arguments in this order, all column vectors).

    ``step(X, t, dt, c, e) -> (X_next, u)``: one RK4 (or ETDRK4, :attr:`~quadctl.sim.loop_spec.LoopSpec.method`) step
    with
    continuous feedback, and the input at its start (continuous specs).
    ``law(X, t, c, e) -> (u, X_sampled)``: the control law at ``X``, and ``X`` with its controller
    states advanced by one controller period (held specs; the input part serves both).
    ``plant(X, u, dt, c, e) -> X_next``: one RK4 step of the plant under a held ``u``; the
    controller states pass through (held specs).
    ``u`` is always the (clipped) command; with rotor dynamics the body gets ``mix_inv f``.
    ``ref(t, c, e) -> x_ref``: the reference state the law regulates to at ``t`` (what the metrics
    of a run measure the error against).
    """

    spec: LoopSpec
    law: ca.Function
    step: ca.Function | None = None
    plant: ca.Function | None = None
    ref: ca.Function | None = None
    remainder: ca.Function | None = None
    """ETDRK4 only: the nonlinear remainder ``N = rhs - L X`` of :func:`etdrk4`'s stages,
    ``(X, t, c, e) -> (N, u)`` (``N`` on the reference's expansion in force over the step, ``u`` the input
    at ``X`` on the one in force at ``t``: :data:`~quadctl.sim.loop_layout.REFERENCE_LAYOUT`) with continuous feedback,
    ``(X, u, c, e) -> N``
    under a held input: what a one-case compiled loop evaluates, its stages' products in
    ``driver.c`` (``qc_etd``, the same operations in the same order)."""

    def functions(self) -> tuple[tuple[str, ca.Function], ...]:
        """(C name, function) of every function the driver calls."""
        named = [("qc_law", self.law)]
        named.append(("qc_plant", self.plant) if self.spec.held else ("qc_step", self.step))
        return (*named, ("qc_ref", self.ref))


@lru_cache(maxsize=32)
def build(spec: LoopSpec) -> LoopFunctions:
    """Build the loop functions of ``spec`` (cached per spec)."""
    model = build_model()
    nz, nx, npl, nl = spec.nz, spec.nx, spec.n_plant, spec.n_lag
    c = ca.SX.sym("c", spec.n_constants)
    parts, offset = {}, 0
    for name, shape in constant_layout(nz, spec.rotors, spec.lag_model, spec.ny, spec.schedule_shape,
                                       spec.n_law_constants, spec.filter_order):
        size = int(np.prod(shape))
        block = c[offset:offset + size]
        parts[name] = ca.reshape(block, *shape) if len(shape) == 2 else block
        offset += size
    mask = ca.DM(np.reshape(np.asarray(spec.pattern, dtype=float), (N_INPUTS, N_STATES), order="F"))
    gain = parts["K"] * mask  # structural zeros vanish from the generated code
    e = ca.SX.sym("e", spec.n_exo)
    if spec.noise:
        disturbance = e[:N_DISTURBANCES]
        sensor = e[N_DISTURBANCES:N_EXO]
    else:
        disturbance, sensor = ca.DM.zeros(N_DISTURBANCES), ca.DM.zeros(N_STATES)
    n_wind_end = spec.n_exo - (N_REFERENCE if spec.reference else 0)
    if spec.wind:
        wind = e[n_wind_end - N_WIND:n_wind_end]

        def f(x, u, p, d):
            return model.f_disturbed_wind(x, u, p, d, wind)
    else:
        f = model.f_disturbed

    def saturate(cmd):
        if spec.saturation == "none":
            return cmd
        if spec.priority:  # roll and pitch kept, then thrust, yaw given up first (quadctl.physics.motors.desaturate)
            return desaturate(cmd, parts["mix"], parts["lo"], parts["hi"], lib=ca)
        act = parts["mix"] @ cmd if spec.saturation == "motors" else cmd
        act = ca.if_else(act < parts["lo"], parts["lo"], act)
        act = ca.if_else(act > parts["hi"], parts["hi"], act)
        return parts["mix_inv"] @ act if spec.saturation == "motors" else act

    ne = spec.n_estimate
    measured = list(spec.measured)
    ng, mf = spec.n_filter, spec.filter_order
    og = npl + nz + nl + spec.n_law + spec.n_buffer  # where the gyro filter's states start

    def gyro(X):
        """The measured body rates ``r_m`` (rad/s): what the gyro filter takes."""
        return X[_P:_P + N_RATES] + sensor[_P:_P + N_RATES]

    def filtered_rates(X):
        """``y = c g + d r_m`` on each rate: what the law takes in place of the measured rates."""
        g, r = X[og:og + ng], gyro(X)
        return ca.vertcat(*[ca.dot(parts["filter_c"], g[k * mf:(k + 1) * mf]) + parts["filter_d"] * r[k]
                            for k in range(N_RATES)])

    def filter_update(X):
        """``A g + b r_m`` on each rate: the filter's next state (held loops) or its rate (continuous)."""
        g, r = X[og:og + ng], gyro(X)
        return ca.vertcat(*[parts["filter_A"] @ g[k * mf:(k + 1) * mf] + parts["filter_b"] * r[k]
                            for k in range(N_RATES)])

    half = ROW_HALF  # one expansion's columns (REFERENCE_LAYOUT holds two)
    n_ref = n_wind_end
    stage = {"over_step": False}  # True while a step's stages are built: they read the step's expansion

    def expansion(t):
        """The expansion the loop reads at ``t`` (:data:`~quadctl.sim.loop_layout.REFERENCE_LAYOUT`): its columns and
        ``s`` (the
        time from its anchor): the one in force at the step's start, or in a step's stages the one in
        force over the step."""
        start = n_ref + (half if stage["over_step"] else 0)
        ref = e[start:start + half]
        return ref, t - ref[0]

    def x_ref(t):
        """The reference state at ``t``: the row's expansion, or the trim drifting at ``x_rate``."""
        if not spec.reference:
            return parts["x_ref"] + parts["x_rate"] * t
        ref, s = expansion(t)
        return ref[1:1 + N_STATES] + s * (ref[1 + N_STATES:1 + 2 * N_STATES]
                                          + s / 2 * ref[1 + 2 * N_STATES:1 + 3 * N_STATES])

    def u_ref(t):
        """The feedforward input at ``t``: the row's, or the trim input."""
        if not spec.reference:
            return parts["u_trim"]
        ref, s = expansion(t)
        return ref[1 + 3 * N_STATES:1 + 3 * N_STATES + N_INPUTS] + s * ref[1 + 3 * N_STATES + N_INPUTS:]

    def design_yaw(psi_ref):
        """The yaw the gain acting at reference yaw ``psi_ref`` was designed at: the trim's, or a yaw
        schedule's value held to its ends (inside them the design's own yaw: no rotation)."""
        if spec.schedule and spec.schedule[0] == "yaw":
            pieces = spec.schedule[1]
            return ca.fmin(ca.fmax(psi_ref, parts["schedule_breaks"][0]), parts["schedule_breaks"][pieces])
        return parts["x_ref"][_PSI]

    def heading_offset(t):
        """rad: the reference's yaw less the yaw its gain was designed at (0 at the trim's heading)."""
        psi_ref = x_ref(t)[_PSI]
        return psi_ref - design_yaw(psi_ref)

    def measured_deviation(X, t):
        """``x_m - x_ref(t)`` in the reference's heading frame (:func:`heading_frame`). A loop without a
        reference holds the trim, whose yaw is the design's: only its yaw error is wrapped (turning by
        a zero angle would cost a sine and a cosine per stage for the same bits)."""
        x_m = X[:N_STATES] + sensor
        if ng:
            x_m = ca.vertcat(x_m[:_P], filtered_rates(X))
        dx = x_m - x_ref(t)
        if not spec.reference:
            return ca.vertcat(dx[:_PSI], wrap_angle(dx[_PSI], ca), dx[_PSI + 1:])
        return heading_frame(dx, heading_offset(t))

    def predicted(xh):
        """``C xh``: the measurements the estimate predicts (a measured rate through the gyro filter's
        model, ``c g_h + d r_h``, when the loop has one: :func:`quadctl.linear.filters.filtered_output`)."""
        if not ng:
            return xh[measured]
        rows = []
        for i in measured:
            k = i - _P
            if 0 <= k < N_RATES:
                gh = xh[N_STATES + k * mf:N_STATES + (k + 1) * mf]
                rows.append(parts["filter_d"] * xh[i] + ca.dot(parts["filter_c"], gh))
            else:
                rows.append(xh[i])
        return ca.vertcat(*rows)

    def innovation(X, t):
        """``y - C xh``: the measured deviation (its rates filtered, with a gyro filter) less its prediction."""
        return measured_deviation(X, t)[measured] - predicted(X[nx - ne:])

    def estimate(X, t):
        """The filter's estimate the law acts on: updated (held loops), or ``xh``; (ne,)."""
        xh = X[nx - ne:]
        return xh + parts["Le"] @ innovation(X, t) if spec.held else xh

    def deviation(X, t):
        """What the law acts on: the measured deviation, or the filter's (updated, held) estimate of it."""
        if not ne:
            return measured_deviation(X, t)
        return estimate(X, t)[:N_STATES]

    def gains(t):
        """(state gain (4, 12), integrator gain (4, nz)) at ``t``: the constants, or the schedule's
        ``G(v)`` at the scheduling value of the reference the law uses."""
        if not spec.schedule:
            return gain, parts.get("Ki")

        variable, pieces, columns, degree = spec.schedule
        heading = (parts["schedule_heading"] + heading_offset(t) if spec.reference and variable != "yaw"
                   else parts["schedule_heading"])
        v = scheduling_value(variable, x_ref(t), heading, lib=ca)
        mask = np.hstack([np.reshape(np.asarray(spec.pattern, dtype=bool), (N_INPUTS, N_STATES), order="F"),
                          np.ones((N_INPUTS, columns - N_STATES), dtype=bool)])
        G = scheduled_gain(v, parts["schedule_breaks"], parts["schedule_coefficients"], pieces, mask, degree)
        return G[:, :N_STATES], (G[:, N_STATES:] if columns > N_STATES else parts.get("Ki"))

    def control(X, t):
        """(u, dz/dt) at loop state ``X`` and time ``t``."""
        z = X[npl:npl + nz]
        err = deviation(X, t)
        state_gain, integral_gain = gains(t)
        cmd = u_ref(t) - state_gain @ err
        if nl:
            cmd = cmd - parts["Kv"] @ X[npl + nz:npl + nz + nl]
        if nz == 0:
            return saturate(cmd), ca.SX(0, 1)
        cmd = cmd - integral_gain @ z
        u = saturate(cmd)
        rate = -ca.vertcat(*[err[i] for i in spec.integral])  # MATLAB lqi: dz/dt = r - y
        if spec.saturation != "none":
            clipped = ca.if_else(ca.fabs(u - cmd) > ANTIWINDUP_TOL, 1, 0)
            frozen = parts["antiwindup"] @ clipped
            rate = ca.if_else(frozen > 0.5, 0, rate)
        return u, rate

    X = ca.SX.sym("X", nx)
    t, dt = ca.SX.sym("t"), ca.SX.sym("dt")
    u_held = ca.SX.sym("u", N_INPUTS)
    params = parts["params"]
    if spec.diagonal_inertia:  # the products of inertia as exact zeros: every term they enter vanishes
        params = ca.vertcat(params[:PRODUCTS.start], ca.DM.zeros(PRODUCTS.stop - PRODUCTS.start),
                            params[PRODUCTS.stop:])

    def rk4(rhs, Y):
        stage["over_step"] = True
        k1 = rhs(Y, t)
        k2 = rhs(Y + dt / 2 * k1, t + dt / 2)
        k3 = rhs(Y + dt / 2 * k2, t + dt / 2)
        k4 = rhs(Y + dt * k3, t + dt)
        stage["over_step"] = False
        return Y + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)

    def body(Y, u):
        """d[x; f]/dt under the command ``u``: the body under ``u``, or under its rotors' thrusts."""
        if not spec.rotors:
            return f(Y[:N_STATES], u, params, disturbance)
        thrust = Y[N_STATES:npl]
        xdot = f(Y[:N_STATES], parts["mix_inv"] @ thrust, params, disturbance)
        return ca.vertcat(xdot, (parts["mix"] @ u - thrust) / parts["tau"])

    def lag_rate(Y, u):
        """dl/dt of the controller's lag model under its command ``u``."""
        return (u - parts["u_trim"] - Y[npl + nz:npl + nz + nl]) / parts["tau_model"]

    n_law = spec.n_law
    if spec.law:  # a PID cascade (quadctl.sim.pid): its own states after the plant's

        command, s_next = pid.law(spec.law, X[npl:npl + n_law], X[:N_STATES] + sensor, x_ref(t), u_ref(t),
                                  parts["law"], parts["mix"], parts["mix_inv"], parts["hi"], parts["thrust_curve"],
                                  parts["Ts"], params[GRAVITY])
        u_now, X_sampled = saturate(command), ca.vertcat(X[:npl], s_next)
    else:
        u_now, z_rate = control(X, t)
        X_sampled = ca.vertcat(X[:npl], X[npl:npl + nz] + parts["Ts"] * z_rate) if nz else X[:npl]
    if nl:  # the lag model's exact ZOH over one sample under the held command
        a = ca.exp(-parts["Ts"] / parts["tau_model"])
        X_sampled = ca.vertcat(X_sampled, a * X[npl + nz:npl + nz + nl] + (1 - a) * (u_now - parts["u_trim"]))
    if spec.delay:  # apply the oldest command, shift the newest in
        b0, nb = spec.buffer_start, spec.n_buffer
        buffer = X[b0:b0 + nb]
        u_now, X_sampled = buffer[nb - N_INPUTS:], ca.vertcat(X_sampled, u_now, buffer[:nb - N_INPUTS])
    if ng:  # the gyro filter takes this sample (held loops)
        X_sampled = ca.vertcat(X_sampled, filter_update(X) if spec.held else X[og:og + ng])
    if ne and spec.held:  # predict from the updated estimate under the applied input
        xc = estimate(X, t)
        X_sampled = ca.vertcat(X_sampled, parts["Ae"] @ xc + parts["Be"] @ (u_now - u_ref(t)))
    elif ne:
        X_sampled = ca.vertcat(X_sampled, X[nx - ne:])
    law = ca.Function("qc_law", [X, t, c, e], ca.cse([u_now, X_sampled]), ["X", "t", "c", "e"], ["u", "X_sampled"])
    ref = ca.Function("qc_ref", [t, c, e], [x_ref(t)], ["t", "c", "e"], ["x_ref"])
    if spec.held:
        def plant_rhs(Y, ts):
            xdot = body(Y, u_held)
            return ca.vertcat(xdot, ca.DM.zeros(nx - npl)) if nx > npl else xdot

        X_next = etdrk4(plant_rhs, X, t, dt, phi_block(c, spec)) if spec.method == "etdrk4" else rk4(plant_rhs, X)
        plant = ca.Function("qc_plant", [X, u_held, dt, c, e], [ca.cse(X_next)],
                            ["X", "u", "dt", "c", "e"], ["X_next"])
        remainder = None
        if spec.method == "etdrk4":
            N = plant_rhs(X, t) - phi_block(c, spec)["lin"] @ X
            remainder = ca.Function("qc_rem", [X, u_held, c, e], [ca.cse(N)], ["X", "u", "c", "e"], ["N"])
        return LoopFunctions(spec=spec, law=law, plant=plant, ref=ref, remainder=remainder)

    def closed_rhs(Y, ts):
        u, rate = control(Y, ts)
        xdot = body(Y, u)
        xdot = ca.vertcat(xdot, rate) if nz else xdot
        xdot = ca.vertcat(xdot, lag_rate(Y, u)) if nl else xdot
        xdot = ca.vertcat(xdot, filter_update(Y)) if ng else xdot
        if ne:  # Kalman-Bucy
            xh = Y[nx - ne:]
            xh_dot = parts["Ae"] @ xh + parts["Be"] @ (u - u_ref(ts)) + parts["Le"] @ innovation(Y, ts)
            xdot = ca.vertcat(xdot, xh_dot)
        return xdot

    remainder = None
    if spec.method == "etdrk4":
        stage["over_step"] = True  # every stage reads the expansion in force over the step
        X_next = etdrk4(closed_rhs, X, t, dt, phi_block(c, spec))
        N = closed_rhs(X, t) - phi_block(c, spec)["lin"] @ X
        stage["over_step"] = False
        remainder = ca.Function("qc_rem", [X, t, c, e], ca.cse([N, u_now]), ["X", "t", "c", "e"], ["N", "u"])
    else:
        X_next = rk4(closed_rhs, X)
    step = ca.Function("qc_step", [X, t, dt, c, e], ca.cse([X_next, u_now]),
                       ["X", "t", "dt", "c", "e"], ["X_next", "u"])
    return LoopFunctions(spec=spec, law=law, step=step, ref=ref, remainder=remainder)


def phi_block(c, spec: LoopSpec) -> dict:
    """The ETDRK4 matrices of :data:`~quadctl.sim.loop_layout.PHI_LAYOUT` in ``c`` (after the loop's constants),
    with the entries outside ``spec.phi_pattern`` zero."""
    nx = spec.nx
    offset = spec.n_constants - spec.n_phi
    mask = (ca.DM(np.reshape(np.asarray(spec.phi_pattern, dtype=float), (nx, nx), order="F"))
            if spec.phi_pattern else None)
    out = {}
    for name in PHI_LAYOUT:
        M = ca.reshape(c[offset:offset + nx * nx], nx, nx)
        out[name] = M * mask if mask is not None else M
        offset += nx * nx
    return out


def etdrk4(rhs, X, t, h, phi: dict):
    """One step of the stiffly accurate exponential Runge-Kutta method of order 4 of Hochbruck and
    Ostermann (SIAM J. Numer. Anal. 43, 2005, eq. 5.19) of ``X' = rhs(X, t)`` split as ``L X + N(X, t)``,
    with ``L`` and the matrices of ``h`` in ``phi`` (:data:`~quadctl.sim.loop_layout.PHI_LAYOUT`), written about the
    step's
    start ``X`` (the linear part acts on ``Y - X``)::

        U2 = X + A21 G1                             G1 = G(X, t) = rhs(X, t)
        U3 = X + A31 G1 + A32 G2                    G2 = G(U2, t + h/2)
        U4 = X + A41 G1 + A42 (G2 + G3)             G3 = G(U3, t + h/2)
        U5 = X + A51 G1 + A52 (G2 + G3) + A54 G4    G4 = G(U4, t + h)
        X+ = X + B1 G1 + B4 G4 + B5 G5              G5 = G(U5, t + h/2)

    with ``G(Y, s) = N(Y, s) + L X = rhs(Y, s) - L (Y - X)``. This is the method's usual form
    (``U2 = e^(hL/2) X + A21 N1``, ...) with ``e^(hL/2) - 1 = A21 L`` and its kin used exactly: in
    floating point the usual form adds the error of those identities times ``X`` at every step, a
    drift away from an equilibrium the loop holds (1e-11 to 1e-10 over 1 s of hover at 1e4 to 1e5
    steps) that this form does not have.

    It keeps its order 4 when ``L`` is stiff and ``N`` is not small (its stiff order conditions): Cox
    and Matthews' four-stage ETDRK4 falls to order 1 to 2 at steps beyond the fast modes' time scale
    on a loop whose remainder couples to them (a mission's tilted thrust). Exact when ``N`` is a
    quadratic in ``t`` along the solution (a linear loop: ``L`` is its matrix).
    """
    L = phi["lin"]
    LX = L @ X

    def G(Y, ts):
        return (rhs(Y, ts) - L @ Y) + LX

    g1 = G(X, t)
    g2 = G(X + phi["A21"] @ g1, t + h / 2)
    g3 = G(X + phi["A31"] @ g1 + phi["A32"] @ g2, t + h / 2)
    g23 = g2 + g3
    g4 = G(X + phi["A41"] @ g1 + phi["A42"] @ g23, t + h)
    g5 = G(X + phi["A51"] @ g1 + phi["A52"] @ g23 + phi["A54"] @ g4, t + h / 2)
    return X + phi["B1"] @ g1 + phi["B4"] @ g4 + phi["B5"] @ g5
