"""The one base of every pydantic model read from a file, and the number types they share.

Every model of a config, thresholds or column-map file derives from :class:`FileModel`:
unknown keys are refused (a typo fails loudly instead of falling back to a default) and every
float, nested in lists, tuples and dicts included, must be finite (``.inf``, ``.nan`` and
overflowing literals such as ``1e999`` are refused with the field path and the value).
"""

from __future__ import annotations

from typing import Annotated

from pydantic import BaseModel, ConfigDict, Field


class FileModel(BaseModel):
    """Base model: ``extra="forbid"``, ``allow_inf_nan=False``."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)


PositiveFloat = Annotated[float, Field(gt=0.0)]
NonNegFloat = Annotated[float, Field(ge=0.0)]
