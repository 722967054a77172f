"""A stack of runs ready for a runner, and its run, however the stack was made (RK4 or ETDRK4,
:func:`quadctl.sim.stack.stack_of`).

:class:`Stack` holds what a runner takes: each case's step plan and record stride, the loops' generated code,
the :class:`~quadctl.sim.cases.Cases` and the exogenous inputs; :func:`run_stack` runs it by a runner. A long
run of one case goes in chunks so Ctrl-C stops it at once, its exogenous rows drawn chunk by chunk
(:class:`~quadctl.sim.exogenous.ExoStream`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from quadctl.sim.cases import Cases
from quadctl.sim.exogenous import ExoStream
from quadctl.sim.loop_spec import LoopSpec


@dataclass(frozen=True)
class Stack:
    """``N`` runs of loops of one structure ready for a runner (:func:`~quadctl.sim.stack.stack_of`): each
    case's step plan and record stride (of its largest step), the loops' generated code (``spec``), the
    :class:`~quadctl.sim.cases.Cases` (RK4: a segment each; ETDRK4: a segment per step of its graded
    schedule), and the exogenous inputs they all take (drawn when the stack runs: :func:`run_stack`)."""

    plans: tuple
    strides: tuple
    spec: LoopSpec
    cases: Cases
    exo: ExoStream | None = None



CHUNK_STEPS = {"compiled": 250_000, "casadi": 20_000}
"""Steps per call into the runner, by backend (~5 M and ~0.2 M steps/s): 0.05 to 0.1 s each, so
Python sees Ctrl-C between calls at once."""


def run_stack(stack: Stack, run, progress=None) -> list[tuple[int, np.ndarray, np.ndarray, np.ndarray]]:
    """The runs of ``stack`` by ``run`` (a runner of its spec, :func:`quadctl.sim.engine.runner`): per case
    ``(done, t, xs, us)``, steps completed, recorded times (s), loop states (r, nx) and inputs (r, 4).

    The exogenous rows are drawn for the whole run at once; a case alone longer than the runner's
    chunk (:data:`CHUNK_STEPS`) runs in chunks instead (:func:`_in_chunks`: Ctrl-C between them, the
    rows drawn as it goes). ``progress(done, total)``, if given, is called with a case alone's steps
    done after each call.
    """
    cases, exo = stack.cases, stack.exo
    total = int(cases.n[:, 0].sum())
    if len(cases) == 1 and total > CHUNK_STEPS.get(run.backend, CHUNK_STEPS["compiled"]):
        return [_in_chunks(run, cases, exo, progress)]
    if exo is not None:
        taken = cases.n > 0  # the rows through the last step of any segment
        rows = exo.samples(0, int(exo.index((cases.k0 + cases.n - 1)[taken], cases.dt[taken]).max(initial=0)))
        cases = cases.starting(cases.x0, exo=[rows] * len(cases))
    out = run.run(cases)
    if progress is not None and len(cases) == 1:
        progress(out[0][0], total)
    return out


def _in_chunks(run, cases: Cases, exo: ExoStream | None, progress=None):
    """``(done, t, xs, us)`` of the one case of ``cases``: segment after segment, each in chunks of
    :data:`CHUNK_STEPS` (whole controller periods, each starting on a sample), a chunk's exogenous rows
    drawn before it; a chunk's final record is the next one's start (kept once)."""
    chunk = CHUNK_STEPS.get(run.backend, CHUNK_STEPS["compiled"])
    total, n_all, last = 0, int(cases.n[:, 0].sum()), int(cases.last[0])
    x = cases.x0[0]
    parts: tuple[list, list, list] = ([], [], [])
    for s in range(last + 1):
        dt, hold, stride = float(cases.dt[s, 0]), int(cases.hold[s, 0]), int(cases.stride[s, 0])
        k0, end = int(cases.k0[s, 0]), int(cases.k0[s, 0] + cases.n[s, 0])
        step = max(hold, chunk // hold * hold)
        while k0 < end:
            m = min(step, end - k0)
            rows, first = None, 0
            if exo is not None:
                first, row = exo.rows(k0, m, dt)
                rows = [row]
            piece = Cases.of(x, cases.c[s, 0], dt, m, stride, cases.lo, cases.hi, hold=hold, k0=k0, exo=rows,
                             exo_first=first, exo_period=cases.exo_period[0])
            (done, t, xs, us), = run.run(piece)
            total += done
            if progress is not None:
                progress(total, n_all)
            final = done < m or (k0 + m >= end and s == last)
            keep = len(t) if final else len(t) - 1
            for part, got in zip(parts, (t, xs, us)):
                part.append(got[:keep])
            if final:
                return total, *(np.concatenate(p) for p in parts)
            x = xs[-1]
            k0 += m
    return total, *(np.concatenate(p) for p in parts)
