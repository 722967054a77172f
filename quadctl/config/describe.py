"""A pydantic ``ValidationError`` as the one line a user reads: file, key path, value, what is allowed.

Imported only when a config (or a value for one of its keys) fails the schema.
"""

from __future__ import annotations

from typing import Any, Literal

from pydantic import ValidationError

from quadctl.config.controller_schema import DelaySamples
from quadctl.config.schema import NAME_RULE
from quadctl.config.schema_paths import section_model
from quadctl.text.messages import hint as _hint
from quadctl.text.messages import key_path, show


def describe(exc: ValidationError, data: Any, label: str) -> str:
    """One line for the first pydantic error: file, key path, value, what is allowed."""
    # an unknown key usually explains the errors after it (a misspelt required key): say it first
    # and a mapping given where a number or a section is allowed (controller.delay) was meant as the section
    # a list never is one of a union's literal choices: that branch's error says nothing
    found = [e for e in exc.errors()
             if not (e["type"] == "literal_error" and isinstance(e.get("input"), list))] or exc.errors()
    found = _meant_branches(found)
    errors = sorted(found, key=lambda e: (e["type"] != "extra_forbidden",
                                          e["type"] == "float_type" and isinstance(e.get("input"), dict)))
    err = errors[0]
    loc = [part for part in err["loc"] if not is_union_tag(part)]
    path = key_path(loc)
    more = _the_others(found, tuple(loc))
    kind = err["type"]
    if kind == "extra_forbidden":
        parent = section_model(loc[:-1])
        allowed = sorted(parent.model_fields) if parent else []
        return f"{label}: {path}: unknown key; {_hint(str(loc[-1]), allowed)}{more}"
    if kind == "missing":
        return f"{label}: {path}: required key is missing; add it{_what_it_takes(loc)}{more}"
    value = _lookup(data, loc)
    if kind in ("int_type", "int_from_float") and isinstance(value, float) and value.is_integer():
        return f"{label}: {path} = {value!r}: must be a whole number; write {int(value)}{more}"
    return f"{label}: {path} = {show(value)}: {expected(err, loc)}{more}"


def _wrong_shape(err: dict) -> bool:
    """A union branch's error that only says the value is not that branch's shape (a number where the
    branch takes a row, a row where it takes a number)."""
    return err["type"] == "list_type" or (err["type"] in ("float_type", "int_type")
                                          and isinstance(err.get("input"), (list, dict)))


def _meant_branches(errors: list) -> list:
    """The errors without a union branch whose every error is of the wrong shape, when another branch of
    the same key has an error of its own: ``Q: [1, .nan, 1]`` was meant as the diagonal, and its NaN is
    the error to report, not that ``1`` is no row of a full matrix."""
    def branch(err):
        loc = err["loc"]
        i = next((k for k, part in enumerate(loc) if is_union_tag(part)), None)
        return None if i is None else (loc[:i], loc[i])

    by_branch: dict = {}
    for e in errors:
        if (b := branch(e)) is not None:
            by_branch.setdefault(b, []).append(e)
    shape_only = {b for b, es in by_branch.items() if all(_wrong_shape(e) for e in es)}
    meant = {b[0] for b in by_branch if b not in shape_only}  # keys with a branch of a fitting shape
    kept = [e for e in errors if (b := branch(e)) is None or b not in shape_only or b[0] not in meant]
    return kept or errors


MORE_NAMED = 3
"""How many of the other failing keys the line names (the rest are counted)."""


def _the_others(found: list, first: tuple) -> str:
    """`` (and 2 more errors, at vehicle.inertia and vehicle.drag)``: the other keys that fail, in
    the schema's order, so one run says where every fix goes; '' when there are none."""
    others: list[str] = []
    for e in found:
        loc = tuple(p for p in e["loc"] if not is_union_tag(p))
        path = key_path(list(loc))
        if loc != first and path not in others:
            others.append(path)
    if not others:
        return ""
    named = others[:MORE_NAMED] + ([f"{len(others) - MORE_NAMED} more"] if len(others) > MORE_NAMED else [])
    where = named[0] if len(named) == 1 else f"{', '.join(named[:-1])} and {named[-1]}"
    return f" (and {len(others)} more error{'s' if len(others) > 1 else ''}, at {where})"


def _what_it_takes(loc: list) -> str:
    """For a missing key: the values it takes (a choice) or its description in brackets, else ''."""
    field = _field_info(loc)
    if field is None:
        return ""
    choices = _literal_values(field.annotation)
    described = f" ({field.description})" if field.description else ""
    return f": {', '.join(choices[:-1])} or {choices[-1]}{described}" if choices else described


UNION_HINTS = {
    "dt": "must be a positive number of seconds, or auto",
    "Q": "must be a list of numbers (the diagonal) or a list of rows (a full matrix)",
    "R": "must be a list of numbers (the diagonal) or a list of rows (a full matrix)",
    "inertia": "must be [Jxx, Jyy, Jzz] or 3 rows [[Jxx, Jxy, Jxz], [Jxy, Jyy, Jyz], [Jxz, Jyz, Jzz]] (kg m^2)",
}
"""Fields whose type is a union: one plain sentence instead of pydantic's per-branch errors."""
LIST_BRANCHES = {"numbering": "the 4 rotor positions, rotor 1 first"}
"""Fields that take a choice or a list: what the list holds, said after the choices."""


def expected(err: dict, loc: list) -> str:
    """What the value should be, in words, with the field's unit from the schema."""
    kind, ctx = err["type"], err.get("ctx") or {}
    names = [p for p in loc if isinstance(p, str)]
    if kind == "finite_number":  # a number of the branch the value was meant for
        return "must be a finite number (not NaN or infinity)"
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
    if kind == "less_than_equal":
        return f"must be at most {ctx.get('le'):g}{unit}"
    if kind in ("int_type", "int_parsing", "int_from_float"):
        return f"must be a whole number{unit}"
    if kind in ("float_type", "float_parsing"):
        return f"must be a number{unit}"
    if kind in ("too_short", "too_long"):
        lo, hi = ctx.get("min_length"), ctx.get("max_length")
        if field is not None:
            meta = {type(m).__name__: m for m in [*field.metadata, *_length_bounds(field.annotation)]}
            lo = getattr(meta.get("MinLen"), "min_length", lo)
            hi = getattr(meta.get("MaxLen"), "max_length", hi)
        count = f"exactly {lo}" if lo is not None and lo == hi else f"at least {lo}" if hi is None else \
            f"at most {hi}" if lo is None else f"{lo} to {hi}"
        items = "item" if (hi if hi is not None else lo) == 1 else "items"
        return f"must be a list of {count} {items}{unit}"
    if kind == "list_type":
        return f"must be a list{unit}"
    if kind in ("string_type",):
        return "must be text"
    if kind in ("bool_type", "bool_parsing"):
        return "must be true or false"
    if kind in ("dict_type", "model_type", "model_attributes_type"):
        return "must be a mapping of keys"
    if kind in ("string_pattern_mismatch", "string_too_long"):  # the config's name, the one text with either
        return f"{NAME_RULE} (it names the folder runs/<name>)"
    if kind == "string_too_short":
        return "must not be empty"
    if kind == "literal_error" and field is not None:
        choices = _literal_values(field.annotation)
        if choices:
            near = _hint(str(err.get("input")), choices)
            listed = f", or a list of {LIST_BRANCHES.get(names[-1], 'values')}" if _admits_list(field.annotation) \
                else ""
            return f"must be one of {', '.join(choices)}{listed}" + (
                f"; {near}" if near.startswith("did you mean") else "")
    if kind == "value_error":  # a validator's own sentence, without pydantic's "Value error, " before it
        return str(ctx.get("error") or err["msg"].removeprefix("Value error, "))
    return err["msg"]


def _literal_values(annotation) -> list[str]:
    """The values a ``Literal[...]`` field takes (inside ``Optional`` or ``Union`` too)."""
    from typing import get_args, get_origin

    if get_origin(annotation) is Literal:
        return [str(v) for v in get_args(annotation)]
    return [v for arg in get_args(annotation) for v in _literal_values(arg)]


def _admits_list(annotation) -> bool:
    """Whether a union annotation has a ``Literal`` branch and a ``list[...]`` branch (a choice or a list)."""
    from typing import Annotated, Union, get_args, get_origin

    if get_origin(annotation) is not Union:
        return False
    branches = [get_args(a)[0] if get_origin(a) is Annotated else a for a in get_args(annotation)]
    return (any(get_origin(b) is Literal for b in branches)
            and any(get_origin(b) is list for b in branches))


def _field_info(loc: list):
    """The pydantic FieldInfo a key path ends at (None inside dict values and lists)."""
    parent = section_model([p for p in loc if not isinstance(p, int)][:-1])
    name = next((p for p in reversed(loc) if isinstance(p, str)), None)
    return parent.model_fields.get(name) if parent is not None and name else None


def is_union_tag(part: Any) -> bool:
    return isinstance(part, str) and (part.startswith(("list[", "literal["))
                                      or part.startswith("function-") or part == "float"
                                      or part.startswith("constrained-") or part == DelaySamples.__name__)


def _lookup(data: Any, loc: list) -> Any:
    for part in loc:
        try:
            data = data[part]
        except (KeyError, IndexError, TypeError):
            return None
    return data


def _length_bounds(annotation) -> list:
    """The ``MinLen``/``MaxLen`` of a list inside an ``Optional[Annotated[list[...], Field(...)]]`` (a field's
    own metadata holds only the outer annotation's)."""
    from typing import get_args

    found = []
    for arg in get_args(annotation):
        found += [m for m in getattr(arg, "metadata", ()) if type(m).__name__ in ("MinLen", "MaxLen")]
        for inner in getattr(arg, "__metadata__", ()):
            found += [m for m in getattr(inner, "metadata", ()) if type(m).__name__ in ("MinLen", "MaxLen")]
        found += _length_bounds(arg) if get_args(arg) else []
    return found
