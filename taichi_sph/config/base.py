"""What every config model shares: the strict base model, the constrained number types, and the helpers
of the cross-field rules (each a validator on the model that owns its keys).

A rule that fails raises `fail(key, message)`: a pydantic error of type `config_rule` that carries the
key relative to the model it runs on; load.format_validation_error joins it to the model's place in the
config and prints "config key '<key>': <message>".
"""

from __future__ import annotations

from typing import Annotated

from pydantic import BaseModel, ConfigDict, Field
from pydantic_core import PydanticCustomError

PosFloat = Annotated[float, Field(gt=0)]
NonNegFloat = Annotated[float, Field(ge=0)]
PosInt = Annotated[int, Field(gt=0)]

#: pydantic error type of a failed cross-field rule
RULE_ERROR = "config_rule"


class Strict(BaseModel):
    """Base: unknown keys are errors; no coercion of strings or booleans to numbers; no inf or nan."""

    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False, validate_default=True)


def fail(key: str, message: str):
    """A cross-field rule failed: `key` (dotted, relative to the model whose validator runs; "" for the
    model itself) and a message."""
    raise PydanticCustomError(RULE_ERROR, "{message}", {"key": key, "message": message})


def need_len(values, n, key):
    if len(values) != n:
        fail(key, f"needs {n} values for dim = {n}, got {len(values)}")


def inside(lo, hi, size, key):
    """The box [lo, hi] lies in the tank interior [0, size]."""
    tol = 1e-12
    for ax, (a, b, s) in enumerate(zip(lo, hi, size)):
        if a < -tol or b > s + tol:
            fail(key, f"lies outside the tank interior [0, {s}] on axis {ax} (min={list(lo)}, max={list(hi)})")
