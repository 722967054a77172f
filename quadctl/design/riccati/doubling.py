"""The doubling steps of :func:`quadctl.design.riccati.stacked.dare_batch`, compiled.

Structure-preserving doubling on a stack of small problems: from ``A0``, ``G0``, ``H0``, with
``W = I + Gk Hk``, ``A(k+1) = Ak W^-1 Ak``, ``G(k+1) = Gk + Ak W^-1 Gk Ak'``,
``H(k+1) = Hk + Ak' Hk W^-1 Ak``, until the step of ``H`` is round-off of it. The C runs one problem
at a time (each stops on its own), compiled once per machine with portable flags (no FMA: it rounds
as written); without a compiler the caller takes the numpy steps. Both give ``H`` to round-off of
each other; the caller's Newton steps and residual check certify it either way.
"""

from __future__ import annotations

import ctypes
import hashlib
from functools import lru_cache

import numpy as np

from quadctl.native.compile import PORTABLE_FLAGS, CompileError, compile_cached

COMPILED_MAX_N = 16
"""Largest ``n`` the compiled steps take (their work arrays are on the C stack); larger stacks take
the numpy steps, whose per-matrix overhead no longer dominates."""
ROUNDOFF_STEPS = 4
"""A doubling step at most this many ``eps`` of ``max |H|`` (entrywise) is round-off: done (the
numpy steps of :func:`quadctl.design.riccati.stacked.dare_batch` take the same rule)."""

SOURCE = r"""
#include <math.h>
#include <float.h>
#define NMAX 16

/* X (n x r, row-major) <- W^-1 X by LU with partial pivoting (W n x n row-major, destroyed);
   a zero pivot makes X NaN (that problem then fails the caller's finiteness check) */
static void lu_solve(long n, long r, double* W, double* X) {
  for (long k = 0; k < n; ++k) {
    long p = k;
    for (long i = k + 1; i < n; ++i) if (fabs(W[i * n + k]) > fabs(W[p * n + k])) p = i;
    if (p != k) {
      for (long j = 0; j < n; ++j) { double t = W[k * n + j]; W[k * n + j] = W[p * n + j]; W[p * n + j] = t; }
      for (long j = 0; j < r; ++j) { double t = X[k * r + j]; X[k * r + j] = X[p * r + j]; X[p * r + j] = t; }
    }
    double piv = W[k * n + k];
    if (piv == 0.0) { for (long j = 0; j < n * r; ++j) X[j] = NAN; return; }
    for (long i = k + 1; i < n; ++i) {
      double f = W[i * n + k] / piv;
      if (f == 0.0) continue;
      for (long j = k + 1; j < n; ++j) W[i * n + j] -= f * W[k * n + j];
      for (long j = 0; j < r; ++j) X[i * r + j] -= f * X[k * r + j];
    }
  }
  for (long k = n - 1; k >= 0; k -= 1) {
    for (long j = 0; j < r; ++j) {
      double s = X[k * r + j];
      for (long i = k + 1; i < n; ++i) s -= W[k * n + i] * X[i * r + j];
      X[k * r + j] = s / W[k * n + k];
    }
  }
}

/* batch problems of n states, A, G, H (batch, n, n) row-major, stepped in place */
void qc_doubling(long batch, long n, long max_steps, double roundoff, double* A, double* G, double* H) {
  double W[NMAX * NMAX], X[NMAX * 2 * NMAX], T[NMAX * NMAX], S[NMAX * NMAX], N2[NMAX * NMAX];
  for (long b = 0; b < batch; ++b) {
    double* a = A + b * n * n; double* g = G + b * n * n; double* h = H + b * n * n;
    for (long k = 0; k < max_steps; ++k) {
      for (long i = 0; i < n; ++i)            /* W = I + G H */
        for (long j = 0; j < n; ++j) {
          double s = i == j ? 1.0 : 0.0;
          for (long l = 0; l < n; ++l) s += g[i * n + l] * h[l * n + j];
          W[i * n + j] = s;
        }
      for (long i = 0; i < n; ++i)            /* X = [A, G] */
        for (long j = 0; j < n; ++j) { X[i * 2 * n + j] = a[i * n + j]; X[i * 2 * n + n + j] = g[i * n + j]; }
      lu_solve(n, 2 * n, W, X);               /* X = [X1, X2] = W^-1 [A, G] */
      for (long i = 0; i < n; ++i)            /* T = A' H */
        for (long j = 0; j < n; ++j) {
          double s = 0.0;
          for (long l = 0; l < n; ++l) s += a[l * n + i] * h[l * n + j];
          T[i * n + j] = s;
        }
      double step_max = 0.0, h_max = 0.0;
      int nan = 0;
      for (long i = 0; i < n; ++i)            /* S = T X1: the step of H */
        for (long j = 0; j < n; ++j) {
          double s = 0.0;
          for (long l = 0; l < n; ++l) s += T[i * n + l] * X[l * 2 * n + j];
          S[i * n + j] = s;
          if (s != s) nan = 1;
          if (fabs(s) > step_max) step_max = fabs(s);
        }
      for (long i = 0; i < n; ++i)            /* H <- sym(H + S) */
        for (long j = 0; j < n; ++j) N2[i * n + j] = h[i * n + j] + S[i * n + j];
      for (long i = 0; i < n; ++i)
        for (long j = 0; j < n; ++j) {
          h[i * n + j] = (N2[i * n + j] + N2[j * n + i]) / 2;
          if (fabs(h[i * n + j]) > h_max) h_max = fabs(h[i * n + j]);
        }
      for (long i = 0; i < n; ++i)            /* T = A X2 */
        for (long j = 0; j < n; ++j) {
          double s = 0.0;
          for (long l = 0; l < n; ++l) s += a[i * n + l] * X[l * 2 * n + n + j];
          T[i * n + j] = s;
        }
      for (long i = 0; i < n; ++i)            /* G <- sym(G + T A') */
        for (long j = 0; j < n; ++j) {
          double s = 0.0;
          for (long l = 0; l < n; ++l) s += T[i * n + l] * a[j * n + l];
          N2[i * n + j] = g[i * n + j] + s;
        }
      for (long i = 0; i < n; ++i)
        for (long j = 0; j < n; ++j) g[i * n + j] = (N2[i * n + j] + N2[j * n + i]) / 2;
      for (long i = 0; i < n; ++i)            /* A <- A X1 */
        for (long j = 0; j < n; ++j) {
          double s = 0.0;
          for (long l = 0; l < n; ++l) s += a[i * n + l] * X[l * 2 * n + j];
          T[i * n + j] = s;
        }
      for (long i = 0; i < n * n; ++i) a[i] = T[i];
      if (nan || !(step_max > roundoff * DBL_EPSILON * h_max)) break;  /* NaN: failed, decided after */
    }
  }
}
"""


def doubling(A: np.ndarray, G: np.ndarray, H: np.ndarray, max_steps: int) -> np.ndarray | None:
    """``H`` after the doubling steps from stacked ``A``, ``G``, ``H`` (batch, n, n), each problem until
    its step is round-off (at most ``max_steps``), in compiled C; None when no C compiler is at hand
    or ``n`` is above :data:`COMPILED_MAX_N` (the caller then takes numpy's stacked steps). The
    inputs are not changed."""
    n = A.shape[-1]
    run = _compiled() if n <= COMPILED_MAX_N else None
    if run is None:
        return None
    A, G, H = (np.array(M, dtype=float, order="C") for M in (A, G, H))  # copies: stepped in place
    run(len(A), n, max_steps, float(ROUNDOFF_STEPS), A.ctypes.data, G.ctypes.data, H.ctypes.data)
    return H


@lru_cache(maxsize=1)
def _compiled():
    """The compiled ``qc_doubling``, or None (no compiler: :class:`quadctl.native.compile.CompileError`)."""

    try:
        library = compile_cached(lambda: SOURCE, PORTABLE_FLAGS,
                                 "riccati doubling " + hashlib.sha256(SOURCE.encode()).hexdigest())
    except CompileError:
        return None
    fn = ctypes.CDLL(str(library)).qc_doubling
    fn.restype = None
    fn.argtypes = [ctypes.c_long, ctypes.c_long, ctypes.c_long, ctypes.c_double, ctypes.c_void_p, ctypes.c_void_p,
                   ctypes.c_void_p]  # the stacks by address: float64, C order (doubling makes them so)
    return fn
