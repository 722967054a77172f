"""A chunk's cases made ready to design: each case's setup from the base's and its varied values
(:class:`CaseSetups`), the plant of its flight condition, shared by the cases that fly it
(:func:`plant_of`, :class:`Plant`), and the two together (:class:`Prepared`).

:mod:`quadctl.sweep.evaluate` designs and simulates what this prepares.
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass
from typing import Any

import numpy as np

from quadctl import config as config_mod
from quadctl import pipeline
from quadctl.config import diagonal_weights_pass
from quadctl.design import discrete
from quadctl.errors import ConfigError, TrimError
from quadctl.setup import setup_of, vary
from quadctl.sweep.config_tree import assign, typed_like


class CaseSetups:
    """The :class:`~quadctl.setup.Setup` of each case of a chunk.

    The reference way validates the case's whole config and builds its setup (~0.2 ms). When every
    varied key is one whose effect on the setup :func:`quadctl.setup.vary` knows (an entry of a
    diagonal ``lqr.<name>.Q`` or ``R``, ``simulation.noise.seed``), the cases' setups are the base's
    with their values put in, the whole chunk at once (a few µs a case), after the checks the whole
    validation makes of them: the type the schema takes (a finite float, a whole number >= 0) and
    the weight checks of :func:`quadctl.config.check_weight` (:func:`~quadctl.config.diagonal_weights_pass`).
    A case whose value fails any check goes the reference way, which words the error, so an invalid
    value gives the same one-line error either way (``tests/sweep/test_case_setups.py`` checks that both
    ways give the same setups and messages).
    """

    def __init__(self, task):
        """``task``: the chunk's :class:`~quadctl.sweep.evaluate.ChunkTask` (its base config, label, varied keys)."""

        self.task = task
        self.kinds: list | None = None
        self.base = None
        self._sizes: dict[tuple[str, str], int] = {}
        try:
            self.cfg = config_mod.from_dict(task.base, task.label)
        except ConfigError:  # a case's values may still make it valid: every case the reference way
            return
        self.base = setup_of(self.cfg)
        if _implausible(self.cfg, task.label):  # every case says so, the reference way
            return
        kinds = [self._kind(keys) for keys in task.keys]
        if all(kind is not None for kind in kinds):
            self.kinds = kinds

    def __call__(self, index: int, values: tuple):
        """The setup of case ``index``; raises ConfigError (one line) when its config is invalid."""
        setup = self.all([(index, values)])[0][0]
        if isinstance(setup, ConfigError):
            raise setup
        return setup

    def all(self, cases) -> list[tuple[Any, bool]]:
        """Per ``(index, values)`` of ``cases``: ``(setup, derived)``, the setup a ConfigError (one line)
        when the case's config is invalid; ``derived``: the base's setup with the values put in (it
        flies the base's plant)."""
        out: list = [None] * len(cases)
        if self.kinds is not None:
            for k, setup in enumerate(self._varied(cases)):
                if setup is not None:
                    out[k] = (setup, True)
        for k, (index, values) in enumerate(cases):
            if out[k] is None:
                try:
                    out[k] = (self.from_config(index, values), False)
                except ConfigError as exc:
                    out[k] = (exc, False)
        return out

    def from_config(self, index: int, values: tuple):
        """The reference way: the case's config assembled, validated and made into its setup."""

        data = self.task.base
        for keys, value in zip(self.task.keys, values):
            data = assign(data, keys, _plain(value))
        label = f"{self.task.label} case {index}"
        cfg = config_mod.from_dict(data, label)
        slips = _implausible(cfg, label)
        if slips:  # as a command refuses the same config on its own: a design for a unit slip is for no vehicle
            raise ConfigError(f"{'; '.join(slips)} (implausible; `allow: [implausible]` accepts it)")
        return setup_of(cfg)

    def _kind(self, keys: tuple):
        """("seed",), ("weight", subsystem, "Q" or "R", index), or None (the reference way)."""
        if keys == ("simulation", "noise", "seed") and self.cfg.simulation.noise is not None:
            return ("seed",)
        if (len(keys) == 4 and keys[0] == "lqr" and keys[1] in self.cfg.lqr and keys[2] in ("Q", "R")
                and type(keys[3]) is int):
            entries = getattr(self.cfg.lqr[keys[1]], keys[2])
            if all(not isinstance(v, list) for v in entries) and 0 <= keys[3] < len(entries):
                return ("weight", *keys[1:])
        return None

    def _varied(self, cases) -> list:
        """Per case, the base setup with its values, or None when one fails a check."""
        import math


        n = len(cases)
        ok = np.ones(n, dtype=bool)
        seeds = None
        columns: dict[tuple[str, str], list] = {}  # (subsystem, "Q" or "R") -> [(entry, values)]
        base_seed = self.cfg.simulation.noise.seed if self.cfg.simulation.noise is not None else None
        for p, kind in enumerate(self.kinds):
            if kind[0] == "seed":
                seeds = [base_seed] * n
                for k, (_, values) in enumerate(cases):
                    seed = typed_like(base_seed, _plain(values[p]))
                    if type(seed) is not int or seed < 0:  # the schema: a strict int >= 0
                        ok[k] = False
                    else:
                        seeds[k] = seed
                continue
            _, name, which, i = kind
            old = getattr(self.cfg.lqr[name], which)[i]
            drawn = np.full(n, float(old))
            for k, (_, values) in enumerate(cases):
                value = typed_like(old, _plain(values[p]))
                if type(value) is not float or not math.isfinite(value):  # the schema: a strict, finite float
                    ok[k] = False
                else:
                    drawn[k] = value
            columns.setdefault((name, which), []).append((i, drawn))
        weights: dict[str, list] = {}
        for (name, which), entries in columns.items():
            diagonal = np.array(getattr(self.cfg.lqr[name], which), dtype=float)
            drawn = np.repeat(diagonal[None], n, axis=0)
            for i, values in entries:  # in the parameters' order: a later one of the same entry wins
                drawn[:, i] = values
            ok &= diagonal_weights_pass(drawn, definite=which == "R")  # the base's own passed already
            size = diagonal.size
            matrices = np.zeros((n, size, size))
            matrices[:, np.arange(size), np.arange(size)] = drawn
            weights.setdefault(name, [None, None])["QR".index(which)] = matrices
        setups = vary(self.base, n, weights={name: tuple(pair) for name, pair in weights.items()}, noise_seeds=seeds)
        return [setup if good else None for setup, good in zip(setups, ok.tolist())]


def _implausible(cfg, label: str) -> list[str]:
    """The warnings of :func:`quadctl.config.notices.notices` (a likely unit slip: a mass in grams, an
    arm in mm), unless the config says ``allow: [implausible]``."""
    from quadctl.config.notices import notices

    if "implausible" in cfg.allow:
        return []
    return [n.message for n in notices(cfg, label) if n.level == "warning"]


class Plant:
    """The linear model of a flight condition and its partition, shared by the cases that fly it;
    the matrices the batched path needs of it are computed once (``cache``)."""

    def __init__(self, linear, decoupled):
        self.linear = linear
        self.decoupled = decoupled
        self.regulated = decoupled.regulated
        """The regulated subsystems (``decoupled.regulated``, which builds its tuple at each call)."""
        self.cache: dict = {}

    def sampled(self, Ts: float):
        """ZOH ``(Ad, Bd)`` of the coupled model at ``Ts``."""

        if ("zoh", Ts) not in self.cache:
            self.cache[("zoh", Ts)] = discrete.c2d(self.linear.A, self.linear.B, Ts)
        return self.cache[("zoh", Ts)]

    def open_loop_eigenvalues(self):
        if "eig" not in self.cache:
            self.cache["eig"] = np.linalg.eigvals(self.linear.A)
        return self.cache["eig"]


@dataclass
class Prepared:
    """A case ready to design: its row head, its resolved setup and its plant."""

    index: int
    head: dict
    setup: Any
    plant: Plant


PLANTS = 16
"""Flight conditions a process keeps (:func:`plant_of`)."""
_plants: OrderedDict[tuple, Any] = OrderedDict()


def plant_of(setup):
    """The :class:`Plant` (or the TrimError) of a setup's flight condition and partition.

    Kept for the :data:`PLANTS` last used: every chunk of a sweep flies the same few, and a
    worker forked after the first case inherits them (a trim, linearization, partition and step
    plan cost as much as many cases' lanes). The key holds everything they
    depend on (:func:`_plant_key`) and a Plant's own cache is keyed by what its entries depend
    on, so a plant is the same object for every case that flies it.
    """

    key = _plant_key(setup)
    if key in _plants:
        _plants.move_to_end(key)
        return _plants[key]
    try:  # the upstream part of the one chain of stages; the designs follow batched (design_all)
        stages = pipeline.Stages(setup)
        plant = Plant(stages.linear, stages.decoupled)
    except TrimError as exc:
        plant = exc
    _plants[key] = plant
    if len(_plants) > PLANTS:
        _plants.popitem(last=False)
    return plant


def _plant_key(setup) -> tuple:
    """What the trim, the linear model and the decoupling depend on."""
    parts = tuple((name, tuple(sub.states), tuple(sub.inputs), sub.regulate, tuple(sub.outputs or ()))
                  for name, sub in setup.partition.items())
    return (setup.vehicle, setup.velocity_ned, setup.position_ned, setup.yaw, setup.trim_wind, parts)


def _plain(value):
    """numpy scalars as Python numbers (the strict config schema takes float, not float64)."""
    if isinstance(value, np.generic):
        return value.item()
    return value
