"""The building blocks of the config's schema: the base every section derives from (frozen, unknown keys
refused) and the strict, finite number types its fields are declared with.

:mod:`quadctl.config.schema` and :mod:`quadctl.config.controller_schema` build their sections of them.
"""

from __future__ import annotations

from typing import Annotated, Union

from pydantic import BaseModel, ConfigDict, Field

Number = Annotated[float, Field(strict=True, allow_inf_nan=False)]
Positive = Annotated[float, Field(strict=True, allow_inf_nan=False, gt=0)]
NonNegative = Annotated[float, Field(strict=True, allow_inf_nan=False, ge=0)]
Vector3 = Annotated[list[Number], Field(min_length=3, max_length=3)]
Matrix = Union[list[Number], list[list[Number]]]

MAX_NOISE = {"force": 1e4, "torque": 1e3}
"""Standard deviation of the process noise, N and N m: far past any gust; 1e300 overflowed the
run's error statistics."""


class Section(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)
