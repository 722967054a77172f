"""What every figure shares: its resolution and colours, a state as drawn (degrees, the height), a time
series thinned to the figure's pixel columns, titles that fit their panels, labels clear of the curves, the PNG
bytes of a figure, and the inputs' limits.
"""

from __future__ import annotations

import io

import numpy as np
from matplotlib.figure import Figure

from quadctl.layout import unit_of

_DEGREES = {"phi", "theta", "psi", "p", "q", "r"}
COLORS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd")
"""The lines' colours, in order (the second, red, also marks limits and failures)."""


_HEIGHT = "pD"
"""Drawn as the height ``-pD`` (m, up positive): NED's down-positive altitude reads upside down."""


DPI = 110
"""The resolution (dots per inch) figures are drawn for: their time series keep every pixel column's
extremes (:func:`pixel_envelope`) at this or any lower resolution. ``quadctl`` saves at it or below."""


def pixel_envelope(x, y, columns: int, *, log: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """The samples of a time series a line drawn ``columns`` pixels wide shows: per column of equal
    width in ``x`` (in ``log10(x)`` with ``log``), its first, lowest, highest and last sample, in order.

    A line through them covers, in every column, the same vertical extent as the line through
    all samples and enters and leaves it at the same points: peaks and spikes one sample wide
    survive, and the data limits (first and last ``x``, lowest and highest ``y``) stay the same.
    A series of at most ``4 columns`` samples, with a non-finite value, or whose ``x`` is not
    increasing (or, with ``log``, not positive) is returned whole.

    Parameters
    ----------
    x : (n,) array_like
        Increasing, such as time (s).
    y : (n,) array_like
    columns : int
        Columns across ``x[0]..x[-1]``: at least the drawn width in pixels.
    log : bool
        Columns of equal width in ``log10(x)`` (a log-scaled axis).

    Returns
    -------
    x, y : (k,) ndarray
        The kept samples, ``k <= 4 columns``.

    Examples
    --------
    >>> t = np.arange(1000.0)
    >>> y = np.zeros(1000); y[123] = 5.0
    >>> tk, yk = pixel_envelope(t, y, 10)
    >>> len(tk), float(yk.max()), float(tk[yk.argmax()])  # a flat column keeps 2 samples, the spike's 3
    (21, 5.0, 123.0)
    """
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    n = len(x)
    if n <= 4 * columns or not (np.isfinite(x).all() and np.isfinite(y).all()):
        return x, y
    if log and x[0] <= 0:
        return x, y
    pos = np.log10(x) if log else x
    span = pos[-1] - pos[0]
    if not span > 0 or (np.diff(pos) < 0).any():
        return x, y
    column = np.minimum(((pos - pos[0]) * (columns / span)).astype(np.intp), columns - 1)
    first = np.flatnonzero(np.r_[True, column[1:] != column[:-1]])
    last = np.r_[first[1:], n] - 1
    size = last - first + 1
    keep = np.zeros(n, dtype=bool)
    keep[first] = keep[last] = True
    for extreme in (np.minimum, np.maximum):
        hit = np.flatnonzero(y == np.repeat(extreme.reduceat(y, first), size))
        keep[hit[np.r_[True, column[hit][1:] != column[hit][:-1]]]] = True  # the first hit of each column
    return x[keep], y[keep]


def trace(ax, x, y, *args, log: bool = False, **kwargs):
    """``ax.plot(x, y, ...)`` of a time series, thinned to the figure's pixel columns at :data:`DPI`
    (:func:`pixel_envelope`).

    With ``log``, the samples at ``x <= 0`` (``t = 0`` on a ``symlog`` axis) are kept whole and the
    rest thinned in columns of equal width in ``log10(x)``."""
    columns = int(np.ceil(ax.get_figure(root=True).get_figwidth() * DPI))
    if log:
        x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
        head = np.searchsorted(x, 0.0, side="right") if len(x) and np.all(np.diff(x) >= 0) else 0
        if 0 < head < len(x):
            tail_x, tail_y = pixel_envelope(x[head:], y[head:], columns, log=True)
            return ax.plot(np.r_[x[:head], tail_x], np.r_[y[:head], tail_y], *args, **kwargs)
    return ax.plot(*pixel_envelope(x, y, columns, log=log), *args, **kwargs)


def wrap_titles(fig: Figure) -> None:
    """Break each axes title wider than its axes into lines (at its ``", "``; within a part still too wide, at
    its words, then a file name's ``_`` and ``-``), so that no title runs past its panel into the next or off
    the figure; the layout engine makes room for the lines when the figure is drawn. Widths are measured once
    the figure is laid out."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    canvas = fig.canvas
    try:
        measure = FigureCanvasAgg(fig)
        fig.draw_without_rendering()
        _wrap_titles(fig, measure.get_renderer())
    finally:
        fig.set_canvas(canvas)


def _wrap_titles(fig: Figure, renderer) -> None:
    for ax in fig.axes:
        title, room = ax.title, ax.get_window_extent(renderer).width
        text = title.get_text()
        if "\n" not in text and title.get_window_extent(renderer).width > room:
            title.set_text(_wrapped(text, title, room, renderer))


def _wrapped(text: str, title, room: float, renderer) -> str:
    """``text`` in lines each at most ``room`` wide (display units) as ``title`` draws it."""

    def fits(line: str) -> bool:
        title.set_text(line)
        return title.get_window_extent(renderer).width <= room

    lines: list[str] = []
    for piece in _pieces(text, fits):
        if lines and fits(lines[-1] + piece):
            lines[-1] += piece
        else:
            lines.append(piece)
    return "\n".join(line.rstrip() for line in lines)


_BREAKS = (", ", " ", "_", "-")
"""Where a title breaks, the first that makes its parts fit: its clauses, words, then a file name's parts."""


def _pieces(text: str, fits, breaks: tuple[str, ...] = _BREAKS) -> list[str]:
    """``text`` cut after its first separator in ``breaks`` (kept with the part before it), each part too wide
    for ``fits`` cut again at the next."""
    if fits(text) or not breaks:
        return [text]
    parts = text.split(breaks[0])
    cut = [p + breaks[0] for p in parts[:-1]] + [parts[-1]]
    return [piece for part in cut if part for piece in _pieces(part, fits, breaks[1:])]


LABEL_SPOTS = tuple((dx * side, dy * up, "left" if side > 0 else "right", "bottom" if up > 0 else "top")
                    for dy in (3, 14, 26) for up in (1, -1) for dx in (3,) for side in (-1, 1))
"""Where :func:`place_labels` tries a label, in order: ``(dx, dy)`` points from the point it marks and its
alignment; above and to the left first, then to the right, below, then farther up and down."""


def place_labels(fig: Figure, labels) -> None:
    """Put each label (an ``Annotation`` of a point, in offset points) at its first spot of :data:`LABEL_SPOTS`
    that lies inside its axes and crosses none of the axes' lines and none of its texts placed before it (the
    spot crossing the fewest when none is clear). Positions are measured once the figure is laid out, and the
    layout is kept (its engine off: it is the costly part of drawing the figure, and the labels take no part in
    it), so the figure is drawn as it was measured.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    labels = list(labels)
    for label in labels:
        label.set_in_layout(False)
    canvas = fig.canvas
    try:
        renderer = FigureCanvasAgg(fig).get_renderer()
        engine = fig.get_layout_engine()
        if engine is not None:  # the layout alone (the axes' places), not a draw of every artist; kept
            engine.execute(fig)
            fig.set_layout_engine("none")
        placed = {id(label) for label in labels}
        fixed = [t for label in labels for t in label.axes.texts if id(t) not in placed]
        done: list = []
        for label in labels:
            ax = label.axes
            frame = ax.get_window_extent(renderer)
            others = [t.get_window_extent(renderer) for t in fixed if t.axes is ax] + [
                t.get_window_extent(renderer) for t in done if t.axes is ax]
            paths = [line.get_transform().transform(line.get_xydata()) for line in ax.get_lines()]
            scores = []
            for spot in LABEL_SPOTS:
                _move(label, spot)
                box = label.get_window_extent(renderer)
                inside = frame.x0 <= box.x0 and box.x1 <= frame.x1 and frame.y0 <= box.y0 and box.y1 <= frame.y1
                score = (0 if inside else 100) + sum(box.overlaps(o) for o in others) + sum(
                    _crosses(p, box) for p in paths)
                scores.append(score)
                if score == 0:
                    break
            _move(label, LABEL_SPOTS[int(np.argmin(scores))])
            done.append(label)
    finally:
        fig.set_canvas(canvas)


def _move(label, spot) -> None:
    dx, dy, ha, va = spot
    label.xyann = (dx, dy)
    label.set_horizontalalignment(ha)
    label.set_verticalalignment(va)


def _crosses(points: np.ndarray, box) -> bool:
    """Whether the polyline ``points`` ((n, 2), display units; a non-finite point breaks it) enters ``box``:
    the segments clipped to the box (Liang and Barsky), each axis's entry before its exit."""
    p0, p1 = points[:-1], points[1:]
    keep = np.isfinite(p0).all(axis=1) & np.isfinite(p1).all(axis=1)
    p0, p1 = p0[keep], p1[keep]
    d = p1 - p0
    enter, leave = np.zeros(len(d)), np.ones(len(d))
    for k, (lo, hi) in enumerate(((box.x0, box.x1), (box.y0, box.y1))):
        flat = d[:, k] == 0
        step = np.where(flat, 1.0, d[:, k])
        t0, t1 = (lo - p0[:, k]) / step, (hi - p0[:, k]) / step
        within = (lo <= p0[:, k]) & (p0[:, k] <= hi)
        enter = np.maximum(enter, np.where(flat, np.where(within, -np.inf, np.inf), np.minimum(t0, t1)))
        leave = np.minimum(leave, np.where(flat, np.where(within, np.inf, -np.inf), np.maximum(t0, t1)))
    return bool(np.any(enter <= leave))


def png_bytes(fig: Figure, dpi: float = DPI) -> bytes:
    """``fig`` as PNG bytes at ``dpi``: the pixels ``fig.savefig(buf, format="png", dpi=dpi)`` writes,
    drawn once.

    ``savefig`` draws a figure with a layout engine twice (once to lay it out, once to render);
    here one draw does both, then the RGBA buffer is encoded as ``savefig`` encodes it. As with
    ``savefig``, the figure keeps its own resolution and canvas afterwards.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.image import imsave

    canvas, resolution = fig.canvas, fig.dpi
    try:
        fig.set_dpi(dpi)
        drawn = FigureCanvasAgg(fig)
        drawn.draw()
        buf = io.BytesIO()
        imsave(buf, drawn.buffer_rgba(), format="png", origin="upper", dpi=dpi)
    finally:
        fig.set_dpi(resolution)
        fig.set_canvas(canvas)
    return buf.getvalue()


def displayed(name: str, values: np.ndarray) -> tuple[np.ndarray, str]:
    """``values`` of state ``name`` as plotted, and their unit (degrees for angles, height for pD)."""
    if name in _DEGREES:
        unit = unit_of(name).replace("rad", "deg")
        return np.rad2deg(values), unit
    if name == _HEIGHT:
        return -np.asarray(values), unit_of(name)
    return values, unit_of(name)


LENGTH_UNITS = ((1.0, "m"), (1e-3, "mm"), (1e-6, "µm"), (1e-9, "nm"))
"""Units a length is drawn in, largest first, each with its size in metres (:func:`length_unit`)."""


def length_unit(values) -> tuple[float, str]:
    """``(size in m, name)`` of the largest of :data:`LENGTH_UNITS` in which the largest ``|values|`` (m) is at
    least 1 (the smallest when even that is not, metres when there is nothing to draw): the axis reads its
    values (340 nm, not 3.4 with a 1e-7 above the axis).

    Examples
    --------
    >>> length_unit([0.0, -3.4e-7]), length_unit([0.02]), length_unit([1.5]), length_unit([0.0])
    ((1e-09, 'nm'), (0.001, 'mm'), (1.0, 'm'), (1.0, 'm'))
    """
    v = np.abs(np.asarray(values, dtype=float))
    peak = float(v[np.isfinite(v)].max()) if np.isfinite(v).any() else 0.0
    if peak == 0.0:
        return LENGTH_UNITS[0]
    return next((unit for unit in LENGTH_UNITS if peak >= unit[0]), LENGTH_UNITS[-1])


def axis_label(name: str) -> str:
    """The axis label of state ``name`` as :func:`displayed` shows it."""
    return "height (-pD)" if name == _HEIGHT else name


def input_limits(actuators) -> tuple[np.ndarray, np.ndarray]:
    """(4,) lowest and (4,) highest value each of ``T, A, E, R`` can take within the actuator limits
    (N, N m; infinite where unlimited). Box limits are themselves; rotor limits bound each input over
    every rotor thrust in ``[min_thrust, max_thrust]`` (the others free): ``T`` in ``[4 min, 4 max]``,
    a torque at the rotors' full differential thrust.

    Examples
    --------
    >>> from quadctl.physics.motors import Motors, actuators_of
    >>> lo, hi = input_limits(actuators_of(Motors(min_thrust=0.0, max_thrust=0.33)))
    >>> lo[0].round(6).tolist(), hi[0].round(6).tolist()
    (0.0, 1.32)
    """
    lo, hi = np.asarray(actuators.lo, dtype=float), np.asarray(actuators.hi, dtype=float)
    if actuators.mode == "box":
        return lo.copy(), hi.copy()
    eff = np.asarray(actuators.mix_inv, dtype=float)  # actuator commands -> [T, A, E, R]
    with np.errstate(invalid="ignore"):  # 0 * inf of an unlimited rotor: that rotor adds nothing
        at_lo, at_hi = np.nan_to_num(eff * lo, nan=0.0), np.nan_to_num(eff * hi, nan=0.0)
    return np.minimum(at_lo, at_hi).sum(axis=1), np.maximum(at_lo, at_hi).sum(axis=1)


def limit_lines(ax, bounds, label: str) -> None:
    """Red lines at the finite ``bounds`` (low, high), labelled once."""
    finite = [b for b in bounds if np.isfinite(b)]
    for k, bound in enumerate(finite):
        ax.axhline(bound, color=COLORS[1], lw=1.0, ls="-.", alpha=0.8, label=label if k == 0 else None)
