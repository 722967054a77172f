"""The config's schema walked by a key path: the section a path points into (:func:`section_model`, for
unknown-key hints and ``key_field``), the model inside an annotation (:func:`first_model`), and the value
a config holds where it leaves a key out (:func:`default_at`: the schema's default, or in
``simulation.plant`` (:data:`PLANT`) the design vehicle's).
"""

from __future__ import annotations

import copy
from typing import Any

from pydantic import BaseModel

from quadctl.config.schema import Config
from quadctl.config.simulation_schema import PlantConfig
from quadctl.config.vehicle_schema import VehicleConfig


def section_model(loc: list) -> type[BaseModel] | None:
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
        inner = first_model(field.annotation)
        expect_key = "dict" in str(field.annotation)
        model = inner if inner is not None else None
    return model if isinstance(model, type) and issubclass(model, BaseModel) else None


def first_model(annotation: Any) -> Any:
    """The BaseModel inside an annotation such as ``dict[str, X] | None``."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    for arg in getattr(annotation, "__args__", ()) or ():
        found = first_model(arg)
        if found is not None:
            return found
    return None


PLANT = ("simulation", "plant")
"""The key path of the simulated vehicle: absent, or any of its keys absent, it is the design vehicle."""


def default_at(tree: Any, keys) -> Any:
    """The value the config holds at the key path ``keys`` where ``tree`` leaves it (or a section on
    the way) out; ``tree`` is a config's data, as YAML gives it or as dumped.

    What an absent value stands for, declared once: in ``simulation.plant`` the design vehicle's
    value (``vehicle:``, itself with the schema's defaults), elsewhere the schema's default (a section
    that takes no required key: all its defaults). None where there is none (``simulation.wind.gusts[0]``).

    Examples
    --------
    >>> default_at({}, ("simulation", "noise", "force"))
    [0.0, 0.0, 0.0]
    >>> default_at({"vehicle": {"mass": 0.5}}, ("simulation", "plant", "mass"))
    0.5
    >>> default_at({}, ("simulation", "wind", "gusts", 0)) is None
    True
    """
    keys = tuple(keys)
    node = tree
    for k, key in enumerate(keys):
        if isinstance(node, dict):
            value = node.get(key)
        elif isinstance(node, list) and isinstance(key, int) and 0 <= key < len(node):
            value = node[key]
        else:
            return None
        node = _absent(tree, keys[:k + 1]) if value is None else value
    return copy.deepcopy(node)  # a copy: the caller may change it, never ``tree``


def _absent(tree: Any, loc: tuple) -> Any:
    """What the value at ``loc`` stands for when the config leaves it out, or None."""
    if loc[:2] == PLANT and len(loc) <= 3:
        given = tree.get("vehicle") if isinstance(tree, dict) else None
        vehicle = {**VehicleConfig().model_dump(mode="json"), **(given if isinstance(given, dict) else {})}
        plant = {key: vehicle.get(key) for key in PlantConfig.model_fields}
        return plant if len(loc) == 2 else plant.get(loc[2])
    if not loc or isinstance(loc[-1], int):
        return None
    model = section_model(list(loc[:-1]))
    field = model.model_fields.get(loc[-1]) if model is not None else None
    if field is None or field.is_required():
        return None
    default = field.get_default(call_default_factory=True)
    if default is None:
        inner = first_model(field.annotation)
        if inner is None or any(f.is_required() for f in inner.model_fields.values()):
            return None
        return inner().model_dump(mode="json")
    return default.model_dump(mode="json") if isinstance(default, BaseModel) else default
