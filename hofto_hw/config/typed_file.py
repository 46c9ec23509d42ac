"""A YAML file validated into a pydantic model, with errors that name file and field.

Shared by the column-map and thresholds readers (one place for "read, expect a mapping,
validate, format the errors").
"""

from __future__ import annotations

from pathlib import Path
from typing import TypeVar

from pydantic import BaseModel, ValidationError

from hofto_hw.config.loader import format_validation_error, read_yaml
from hofto_hw.errors import ConfigError

M = TypeVar("M", bound=BaseModel)


def read_typed_yaml(path: str | Path, what: str, model: type[M]) -> M:
    """Read ``path`` (a ``what``, e.g. "column map") and validate it as ``model``."""
    path = Path(path)
    data = read_yaml(path, what)
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: expected a mapping at the top level of the {what}")
    try:
        return model.model_validate(data)
    except ValidationError as err:
        raise ConfigError(format_validation_error(str(path), err)) from None
