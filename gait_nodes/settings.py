"""Checks shared by the nodes' settings dataclasses."""

from __future__ import annotations

import math

from gait_nodes.errors import ParameterError


def checked_number(values: dict, name: str, low: float, high: float,
                   low_open: bool = False) -> float:
    """``values[name]`` as a float in ``[low, high]`` (``(low, high]`` when ``low_open``).

    Raises:
        ParameterError: Not a finite number in the range; the message gives both.
    """
    value = values[name]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
            or not (low < value if low_open else low <= value) or not value <= high:
        bracket = '(' if low_open else '['
        raise ParameterError(f'{name} must be a number in {bracket}{low}, {high}], got {value!r}')
    return float(value)
