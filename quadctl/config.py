"""The YAML config: schema, validation, loading and the bundled configs.

A config is validated whole on load: unknown keys are refused (with the nearest valid
key suggested), numbers must be finite, names must exist, and every error is one
:class:`~quadctl.errors.ConfigError` line naming the file, the key path, the value
and what is allowed.
"""

from __future__ import annotations

import difflib
import hashlib
import json
import math
import re
from importlib import resources
from pathlib import Path
from typing import Annotated, Any, Literal, Optional, Union

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from quadctl.errors import ConfigError
from quadctl.layout import INPUT_NAMES, REPORT_PARTITION, STATE_NAMES

DEFAULT_CONFIG = "forward"
"""Bundled config used when no ``--config`` is given: the report's forward-flight case."""

Number = Annotated[float, Field(strict=True, allow_inf_nan=False)]
Positive = Annotated[float, Field(strict=True, allow_inf_nan=False, gt=0)]
NonNegative = Annotated[float, Field(strict=True, allow_inf_nan=False, ge=0)]
Vector3 = Annotated[list[Number], Field(min_length=3, max_length=3)]
Matrix = Union[list[Number], list[list[Number]]]


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class VehicleConfig(_Section):
    """Vehicle parameters, SI units."""

    mass: Positive = Field(0.068, description="kg")
    gravity: Positive = Field(9.81, description="m/s^2")
    inertia: Annotated[list[Positive], Field(min_length=3, max_length=3)] = Field(
        [0.69e-4, 0.775e-4, 1.5e-4], description="kg m^2, diagonal [Jxx, Jyy, Jzz]")
    drag: Annotated[list[NonNegative], Field(min_length=3, max_length=3)] = Field(
        [0.22, 0.22, 0.0], description="Kc diagonal; rotor drag force is -T Kc V_b (1/(m/s))")


class TrimConfig(_Section):
    """The flight condition to trim about."""

    velocity_ned: Vector3 = Field([0.0, 0.0, 0.0], description="m/s, earth frame (down positive)")
    position_ned: Vector3 = Field([0.0, 0.0, -1.0], description="m; altitude 1 m is pD = -1")
    yaw: Number = Field(0.0, description="rad, heading psi")


class SubsystemConfig(_Section):
    """One block of the partition: its states, its inputs, and whether it is regulated."""

    states: Annotated[list[str], Field(min_length=1)]
    inputs: Annotated[list[str], Field(min_length=1)]
    regulate: bool = True
    outputs: list[str] | None = Field(None, description="measured states (C rows); default all")


class LqrWeights(_Section):
    """LQR weights of one subsystem: a list is a diagonal, a nested list a full matrix.

    With ``integral`` (LQI, as MATLAB ``lqi``), ``Q`` weighs ``[states; integrals]``: it has one
    entry more per integrated state, in the order of ``integral``.
    """

    Q: Matrix
    R: Matrix
    integral: list[str] = Field(
        default_factory=list, description="states of this subsystem whose error is integrated (LQI)")


class NoiseConfig(_Section):
    """Process and sensor noise: zero-mean Gaussian, drawn every ``period`` and held in between."""

    seed: Annotated[int, Field(strict=True, ge=0)] = Field(0, description="random seed; same seed, same run")
    force: Annotated[list[NonNegative], Field(min_length=3, max_length=3)] = Field(
        [0.0, 0.0, 0.0], description="N, standard deviation of the body-frame force disturbance")
    torque: Annotated[list[NonNegative], Field(min_length=3, max_length=3)] = Field(
        [0.0, 0.0, 0.0], description="N m, standard deviation of the body torque disturbance")
    sensor: dict[str, NonNegative] = Field(
        default_factory=dict, description="state name -> standard deviation of its measurement (state units)")
    period: Optional[Positive] = Field(
        None, description="s between noise samples; default the controller period, or 5 ms if continuous")


class PlantConfig(_Section):
    """The simulated vehicle where it differs from the design model (model mismatch)."""

    mass: Optional[Positive] = Field(None, description="kg")
    gravity: Optional[Positive] = Field(None, description="m/s^2")
    inertia: Optional[Annotated[list[Positive], Field(min_length=3, max_length=3)]] = Field(
        None, description="kg m^2, diagonal")
    drag: Optional[Annotated[list[NonNegative], Field(min_length=3, max_length=3)]] = Field(
        None, description="Kc diagonal")


class SimulationConfig(_Section):
    """Closed-loop simulation settings."""

    duration: Positive = Field(10.0, description="s")
    dt: Union[Literal["auto"], Positive] = Field("auto", description="s, or auto")
    initial_offset: dict[str, Number] = Field(
        default_factory=dict, description="state name -> offset from trim (state units)")
    noise: Optional[NoiseConfig] = Field(None, description="process and sensor noise; absent: none")
    plant: Optional[PlantConfig] = Field(
        None, description="simulated vehicle parameters that differ from vehicle: (model mismatch)")
    max_samples: Annotated[int, Field(strict=True, ge=2)] = Field(
        20_000, description="samples kept (every k-th RK4 step and the last) for sim.npz, metrics and plots")


class ControllerConfig(_Section):
    """How the controller runs on the flight computer."""

    rate: Optional[Positive] = Field(None, description="Hz; absent: continuous feedback, as in the report")
    design: Literal["discrete", "continuous"] = Field(
        "discrete", description="with a rate: discrete LQR at that rate (lqrd), or the continuous LQR "
        "run at that rate (emulation)")


class MotorsConfig(_Section):
    """Four rotors; defaults: the Parrot Mambo (MODEL.md, "Motors")."""

    layout: Literal["x", "+"] = Field("x", description="x: rotors at +-45 deg from the nose; +: on the axes")
    arm_length: Positive = Field(0.0624, description="m, from the centre to each rotor axis")
    thrust_coefficient: Positive = Field(4.72e-8, description="N/(rad/s)^2, rotor thrust = k omega^2")
    torque_coefficient: Positive = Field(0.00241, description="N m of yaw reaction torque per N of thrust")
    min_thrust: NonNegative = Field(0.0, description="N per rotor")
    max_thrust: Positive = Field(0.33, description="N per rotor")


InputLimits = Annotated[list[Number], Field(min_length=2, max_length=2)]


class Config(_Section):
    """A whole quadctl config (see the README's config reference)."""

    name: Annotated[str, Field(min_length=1, pattern=r"^[A-Za-z0-9_.-]+$")]
    description: str = ""
    vehicle: VehicleConfig = VehicleConfig()
    trim: TrimConfig = TrimConfig()
    subsystems: dict[str, SubsystemConfig] | None = None
    lqr: dict[str, LqrWeights]
    simulation: SimulationConfig = SimulationConfig()
    controller: ControllerConfig = ControllerConfig()
    motors: Optional[MotorsConfig] = Field(None, description="rotor layout and thrust limits; saturates the inputs")
    limits: Optional[dict[str, InputLimits]] = Field(
        None, description="input name -> [low, high] (N or N m); box limits when there is no motors:")

    def partition(self) -> dict[str, SubsystemConfig]:
        """The subsystems in force: the config's, or the report's five."""
        if self.subsystems is not None:
            return dict(self.subsystems)
        return {k: SubsystemConfig(**v) for k, v in REPORT_PARTITION.items()}

    def digest(self) -> str:
        """sha256 of the validated config (canonical JSON): the provenance of every artifact."""
        text = json.dumps(self.model_dump(mode="json"), sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(text.encode()).hexdigest()

    def to_yaml(self) -> str:
        """The validated config as YAML (all defaults filled in)."""
        return yaml.safe_dump(self.model_dump(mode="json"), sort_keys=False)


# ---------------------------------------------------------------------------------------
# Loading


class YamlLoader(yaml.SafeLoader):
    """PyYAML's safe loader, but ``1e5`` and ``68e-3`` are numbers (YAML 1.1 needs a dot)."""


YamlLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"""^(?:[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+]?[0-9]+)?
                |[-+]?(?:[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)
                |\.[0-9_]+(?:[eE][-+]?[0-9]+)?
                |[-+]?\.(?:inf|Inf|INF)
                |\.(?:nan|NaN|NAN))$""", re.X),
    list("-+0123456789."))


def load_yaml(text: str, label: str) -> Any:
    """Parse YAML text; a syntax error is a ConfigError with line and column."""
    try:
        return yaml.load(text, Loader=YamlLoader)  # noqa: S506 - a SafeLoader subclass
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise ConfigError(f"{label}: YAML syntax error{where}: {problem}; fix the YAML") from None


def bundled_names() -> list[str]:
    """Names of the configs that ship with quadctl (without ``.yaml``)."""
    folder = resources.files("quadctl") / "configs"
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".yaml"))


def resolve(spec: str | Path | None) -> tuple[str, str]:
    """Find a config: an existing path, else a bundled name (with or without ``.yaml``).

    Returns
    -------
    (label, text) : the file name to cite in errors, and its YAML text.

    Raises
    ------
    ConfigError
        The path does not exist and no bundled config has that name, or it cannot be read.
    """
    spec = DEFAULT_CONFIG if spec is None else str(spec)
    path = Path(spec)
    if path.is_dir():
        raise ConfigError(f"{spec}: is a folder, not a config file; give a .yaml file")
    if path.exists():
        try:
            return str(path), path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
            raise ConfigError(f"{spec}: cannot read the config ({reason}); check the file") from None
    name = re.sub(r"\.ya?ml$", "", spec)
    if "/" not in name and name in bundled_names():
        res = resources.files("quadctl") / "configs" / f"{name}.yaml"
        return f"{name}.yaml", res.read_text(encoding="utf-8")
    near = difflib.get_close_matches(name, bundled_names(), n=1)
    hint = f"did you mean `{near[0]}`? " if near and "/" not in name else ""
    raise ConfigError(
        f"{spec}: no such file and no bundled config of that name; {hint}"
        f"bundled: {', '.join(bundled_names())}")


def load(spec: str | Path | None = None) -> Config:
    """Load and validate a config from a path or a bundled name (default: ``forward``).

    Raises
    ------
    ConfigError
        With one line naming the file, key path, value and the fix.
    """
    label, text = resolve(spec)
    return parse(text, label)


def parse(text: str, label: str = "<config>") -> Config:
    """Validate YAML text as a config; ``label`` names it in errors."""
    return from_dict(load_yaml(text, label), label)


def from_dict(data: Any, label: str = "<config>") -> Config:
    """Validate a mapping (as YAML gives it) as a config."""
    if not isinstance(data, dict):
        kind = "empty" if data is None else f"a {type(data).__name__}"
        raise ConfigError(f"{label}: the config is {kind}, not a mapping of keys; "
                          "start from `quadctl configs --show forward`")
    try:
        cfg = Config.model_validate(data)
    except ValidationError as exc:
        raise ConfigError(_describe(exc, data, label)) from None
    _check_semantics(cfg, label)
    return cfg


def _describe(exc: ValidationError, data: Any, label: str) -> str:
    """One line for the first pydantic error: file, key path, value, what is allowed."""
    # an unknown key usually explains the errors after it (a misspelt required key): say it first
    errors = sorted(exc.errors(), key=lambda e: e["type"] != "extra_forbidden")
    err = errors[0]
    loc = [part for part in err["loc"] if not _is_union_tag(part)]
    path = key_path(loc)
    distinct = {tuple(p for p in e["loc"] if not _is_union_tag(p)) for e in exc.errors()}
    n_more = len(distinct) - 1
    more = f" (and {n_more} more error{'s' if n_more > 1 else ''})" if n_more else ""
    kind = err["type"]
    if kind == "extra_forbidden":
        parent = _section_model(loc[:-1])
        allowed = sorted(parent.model_fields) if parent else []
        return f"{label}: {path}: unknown key; {_hint(str(loc[-1]), allowed)}{more}"
    if kind == "missing":
        return f"{label}: {path}: required key is missing; add it{more}"
    value = _lookup(data, loc)
    if kind in ("int_type", "int_from_float") and isinstance(value, float) and value.is_integer():
        return f"{label}: {path} = {value!r}: must be a whole number; write {int(value)}{more}"
    return f"{label}: {path} = {_show(value)}: {_expected(err, loc)}{more}"


UNION_HINTS = {
    "dt": "must be a positive number of seconds, or auto",
    "Q": "must be a list of numbers (the diagonal) or a list of rows (a full matrix)",
    "R": "must be a list of numbers (the diagonal) or a list of rows (a full matrix)",
}
"""Fields whose type is a union: one plain sentence instead of pydantic's per-branch errors."""


def _expected(err: dict, loc: list) -> str:
    """What the value should be, in words, with the field's unit from the schema."""
    kind, ctx = err["type"], err.get("ctx") or {}
    names = [p for p in loc if isinstance(p, str)]
    if names and names[-1] in UNION_HINTS:
        return UNION_HINTS[names[-1]]
    field = _field_info(loc)
    unit = f" ({field.description})" if field is not None and field.description else ""
    if kind == "finite_number":
        return "must be a finite number (not NaN or infinity)"
    if kind == "greater_than":
        return f"must be greater than {ctx.get('gt')}{unit}"
    if kind == "greater_than_equal":
        return f"must be at least {ctx.get('ge')}{unit}"
    if kind in ("int_type", "int_parsing", "int_from_float"):
        return f"must be a whole number{unit}"
    if kind in ("float_type", "float_parsing"):
        return f"must be a number{unit}"
    if kind in ("too_short", "too_long"):
        lo, hi = ctx.get("min_length"), ctx.get("max_length")
        if field is not None:
            meta = {type(m).__name__: m for m in field.metadata}
            lo = getattr(meta.get("MinLen"), "min_length", lo)
            hi = getattr(meta.get("MaxLen"), "max_length", hi)
        count = f"exactly {lo}" if lo is not None and lo == hi else f"at least {lo}" if hi is None else \
            f"{lo} to {hi}"
        return f"must be a list of {count} items{unit}"
    if kind == "list_type":
        return f"must be a list{unit}"
    if kind in ("string_type",):
        return "must be text"
    if kind in ("bool_type", "bool_parsing"):
        return "must be true or false"
    if kind in ("dict_type", "model_type", "model_attributes_type"):
        return "must be a mapping of keys"
    if kind == "string_pattern_mismatch":
        return "must use only letters, digits, '_', '.' and '-'"
    if kind == "string_too_short":
        return "must not be empty"
    return err["msg"]


def _field_info(loc: list):
    """The pydantic FieldInfo a key path ends at (None inside dict values and lists)."""
    parent = _section_model([p for p in loc if not isinstance(p, int)][:-1])
    name = next((p for p in reversed(loc) if isinstance(p, str)), None)
    return parent.model_fields.get(name) if parent is not None and name else None


def _is_union_tag(part: Any) -> bool:
    return isinstance(part, str) and (part.startswith("list[") or part in ("literal['auto']",)
                                      or part.startswith("function-") or part == "float")


def _section_model(loc: list) -> type[BaseModel] | None:
    """The schema section that the key path ``loc`` points into (for unknown-key hints)."""
    model: Any = Config
    expect_key = False
    for part in loc:
        if isinstance(part, int):
            continue
        if expect_key:  # a name inside subsystems/lqr/initial_offset: the value model follows
            expect_key = False
            continue
        field = model.model_fields.get(part) if isinstance(model, type) else None
        if field is None:
            return None
        inner = _first_model(field.annotation)
        expect_key = "dict" in str(field.annotation)
        model = inner if inner is not None else None
    return model if isinstance(model, type) and issubclass(model, BaseModel) else None


def _first_model(annotation: Any) -> Any:
    """The BaseModel inside an annotation such as ``dict[str, X] | None``."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    for arg in getattr(annotation, "__args__", ()) or ():
        found = _first_model(arg)
        if found is not None:
            return found
    return None


def key_path(loc: list | tuple) -> str:
    """``['lqr', 'roll', 'Q', 1]`` -> ``'lqr.roll.Q[1]'``."""
    out = ""
    for part in loc:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out or "<top level>"


def _lookup(data: Any, loc: list) -> Any:
    for part in loc:
        try:
            data = data[part]
        except (KeyError, IndexError, TypeError):
            return None
    return data


def _show(value: Any) -> str:
    """A value as the user wrote it (whole floats without ``.0``), cut to 60 characters."""
    def plain(v):
        if isinstance(v, (list, tuple)):
            return [plain(x) for x in v]
        if isinstance(v, float) and v.is_integer() and abs(v) < 1e15:
            return int(v)
        return v

    value = plain(value)
    text = repr(value) if isinstance(value, float) else json.dumps(value)
    return text if len(text) <= 60 else text[:57] + "..."


# ---------------------------------------------------------------------------------------
# Checks across fields


def _check_semantics(cfg: Config, label: str) -> None:
    def fail(path: str, value: Any, why: str) -> None:
        raise ConfigError(f"{label}: {path} = {_show(value)}: {why}")

    partition = cfg.partition()
    where = "subsystems" if cfg.subsystems is not None else "subsystems (the report's default)"
    seen_states: dict[str, str] = {}
    seen_inputs: dict[str, str] = {}
    for name, sub in partition.items():
        for i, state in enumerate(sub.states):
            if state not in STATE_NAMES:
                fail(f"subsystems.{name}.states[{i}]", state, _unknown(state, STATE_NAMES, "state"))
            if state in seen_states:
                fail(f"subsystems.{name}.states[{i}]", state,
                     f"state already in subsystem `{seen_states[state]}`; each state belongs to one subsystem")
            seen_states[state] = name
        allowed = INPUT_NAMES if sub.regulate else INPUT_NAMES + STATE_NAMES
        for i, inp in enumerate(sub.inputs):
            if inp not in allowed:
                kind = "input" if sub.regulate else "input or state"
                fail(f"subsystems.{name}.inputs[{i}]", inp, _unknown(inp, allowed, kind))
            if inp in INPUT_NAMES:
                if inp in seen_inputs:
                    fail(f"subsystems.{name}.inputs[{i}]", inp,
                         f"input already drives subsystem `{seen_inputs[inp]}`; give each input to one subsystem")
                seen_inputs[inp] = name
            elif inp in sub.states:
                fail(f"subsystems.{name}.inputs[{i}]", inp, "a subsystem's own state cannot be its input")
        for i, out in enumerate(sub.outputs or []):
            if out not in sub.states:
                fail(f"subsystems.{name}.outputs[{i}]", out,
                     f"outputs must be states of this subsystem: {', '.join(sub.states)}")
    regulated = {n: s for n, s in partition.items() if s.regulate}
    for inp in INPUT_NAMES:
        if inp not in seen_inputs:
            fail(where, sorted(regulated), f"input `{inp}` is not assigned to any regulated subsystem; "
                 "add it to one subsystem's inputs")
    for name in cfg.lqr:
        if name not in partition:
            fail(f"lqr.{name}", name, _unknown(name, list(regulated), "regulated subsystem"))
        if not partition[name].regulate:
            fail(f"lqr.{name}", name, "this subsystem has regulate: false; remove its weights or regulate it")
    for name, sub in regulated.items():
        if name not in cfg.lqr:
            fail("lqr", sorted(cfg.lqr), f"regulated subsystem `{name}` has no weights; "
                 f"add lqr.{name} with Q ({len(sub.states)} values) and R ({len(sub.inputs)})")
        weights = cfg.lqr[name]
        for i, state in enumerate(weights.integral):
            if state not in sub.states:
                fail(f"lqr.{name}.integral[{i}]", state,
                     f"not a state of subsystem `{name}`; integrate one of {', '.join(sub.states)}")
            if state in weights.integral[:i]:
                fail(f"lqr.{name}.integral[{i}]", state, "listed twice; integrate each state once")
        check_weight(weights.Q, len(sub.states) + len(weights.integral), f"lqr.{name}.Q", label,
                     definite=False, names=[*sub.states, *(f"integral of {s}" for s in weights.integral)])
        check_weight(weights.R, len(sub.inputs), f"lqr.{name}.R", label, definite=True,
                     names=sub.inputs)
    for state, value in cfg.simulation.initial_offset.items():
        if state not in STATE_NAMES:
            fail(f"simulation.initial_offset.{state}", value, _unknown(state, STATE_NAMES, "state"))
        limit = MAX_TILT_OFFSET if state in ("phi", "theta") else 2 * math.pi if state == "psi" else None
        if limit is not None and abs(value) >= limit:
            fail(f"simulation.initial_offset.{state}", value, _degrees_hint(value, limit))
    if abs(cfg.trim.yaw) > 2 * math.pi:
        fail("trim.yaw", cfg.trim.yaw, _degrees_hint(cfg.trim.yaw, 2 * math.pi))
    _check_flight(cfg, fail)


def _check_flight(cfg: Config, fail) -> None:
    """Controller rate, motors, limits and noise (issue 5)."""
    if cfg.motors is not None and cfg.limits is not None:
        fail("limits", cfg.limits, "give either motors: (limits from the rotors) or limits:, not both")
    if cfg.motors is not None and cfg.motors.min_thrust >= cfg.motors.max_thrust:
        fail("motors.min_thrust", cfg.motors.min_thrust,
             f"must be below motors.max_thrust = {cfg.motors.max_thrust:g} N")
    for name, (low, high) in (cfg.limits or {}).items():
        if name not in INPUT_NAMES:
            fail(f"limits.{name}", [low, high], _unknown(name, INPUT_NAMES, "input"))
        if not low < high:
            fail(f"limits.{name}", [low, high], "must be [low, high] with low < high")
    noise = cfg.simulation.noise
    for state, value in (noise.sensor if noise else {}).items():
        if state not in STATE_NAMES:
            fail(f"simulation.noise.sensor.{state}", value, _unknown(state, STATE_NAMES, "state"))


MAX_TILT_OFFSET = math.radians(85.0)
"""Roll or pitch offsets at or past 85 deg start outside the Euler model's valid range."""


def _degrees_hint(value: float, limit: float) -> str:
    """Angles are in rad: say what the value would be, and what the user likely meant."""
    return (f"that is {math.degrees(value):.0f} deg, beyond {math.degrees(limit):.0f} deg; angles are in rad: "
            f"for {value:g} deg write {math.radians(value):.4g}")


def _unknown(name: str, allowed, kind: str) -> str:
    return f"unknown {kind}; {_hint(name, allowed)}"


def _hint(name: str, allowed) -> str:
    """``did you mean `X`?`` (case first, then spelling), else the list of what is allowed."""
    same_but_case = [a for a in allowed if a.lower() == name.lower()]
    near = same_but_case or difflib.get_close_matches(name, list(allowed), n=1)
    return f"did you mean `{near[0]}`?" if near else f"allowed: {', '.join(allowed)}"


SYMMETRY_RTOL = 1e-10
"""Relative tolerance of the symmetry test, scaled by the matrix's largest entry."""
DEFINITENESS_RTOL = 1e-12
"""Eigenvalues above ``-rtol * max|eig|`` count as nonnegative (PSD test), as in SciPy's ``_are``."""


def weight_matrix(value: list, size: int):
    """A weight as a (size, size) numpy array: a list is a diagonal, a nested list a matrix."""
    import numpy as np

    arr = np.asarray(value, dtype=float)
    return np.diag(arr) if arr.ndim == 1 else arr


def check_weight(value: list, size: int, path: str, label: str, *, definite: bool,
                 names: list[str]) -> None:
    """Check Q (PSD) or R (PD): size, symmetry, definiteness; raise ConfigError naming ``path``."""
    import numpy as np

    nested = bool(value) and isinstance(value[0], list)
    if nested and any(not isinstance(row, list) for row in value):
        raise ConfigError(f"{label}: {path}: mixes numbers and rows; give a list (diagonal) or a list of rows")
    shape = (len(value), len(value[0])) if nested and value else (len(value),)
    expect = f"{size} value{'s' if size != 1 else ''} (one per {', '.join(names)}) or a {size}x{size} matrix"
    if (not nested and len(value) != size) or (nested and (len(value) != size or any(
            len(row) != size for row in value))):
        got = "x".join(map(str, shape)) if nested else f"{len(value)} values"
        raise ConfigError(f"{label}: {path} = {_show(value)}: expected {expect}, got {got}")
    if nested:
        mat = weight_matrix(value, size)
        scale = max(float(np.abs(mat).max()), 1.0)
        if not np.allclose(mat, mat.T, rtol=0, atol=SYMMETRY_RTOL * scale):
            raise ConfigError(f"{label}: {path} = {_show(value)}: not symmetric; make it equal to its transpose")
        eig = np.linalg.eigvalsh((mat + mat.T) / 2)
    else:  # a diagonal is symmetric and its eigenvalues are its entries (sweeps validate thousands)
        eig = np.sort(np.asarray(value, dtype=float))
    floor = DEFINITENESS_RTOL * max(float(np.abs(eig).max()), 1e-300)
    if definite and eig.min() <= floor:
        raise ConfigError(f"{label}: {path} = {_show(value)}: must be positive definite "
                          f"(smallest eigenvalue {eig.min():.3g}); use positive weights")
    if not definite and eig.min() < -floor:
        raise ConfigError(f"{label}: {path} = {_show(value)}: must be positive semidefinite "
                          f"(smallest eigenvalue {eig.min():.3g}); use nonnegative weights")
