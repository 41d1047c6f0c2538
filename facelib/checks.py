"""The checks every setting and argument shares: one error wording for a choice, a
number, an integer, a probability, a flag; and a dataclass with some fields changed.

Each raises ValueError naming the value, what it got and what is allowed.  Python's
``bool`` is an ``int``: every numeric check refuses True and False, so that
``steps=True`` is an error, not one step.  Checks particular to one idea (a label, a
split, a mesh) stay beside that idea.
"""

from __future__ import annotations

import math
from dataclasses import fields, replace

# the networks compute in float32: a number beyond this overflows them
FLOAT32_MAX = 3.4e38


def _is_number(value):
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def check_choice(name, value, allowed):
    """``value`` is one of ``allowed``."""
    if value not in allowed:
        raise ValueError(f"{name} must be one of {tuple(allowed)}, got {value!r}")


def check_number(name, value, low=0.0, high=None, allow_none=False):
    """A finite number in [low, high] (high None: FLOAT32_MAX; None itself too with
    ``allow_none``)."""
    if value is None and allow_none:
        return
    top = FLOAT32_MAX if high is None else high
    if not _is_number(value) or not low <= value <= top:
        if high is not None:
            wanted = f"a number in [{low:g}, {high:g}]"
        else:
            wanted = (
                f"a {'non-negative number' if low == 0 else f'number >= {low}'} (and"
                " finite, at most 3.4e38: the networks compute in float32)"
            )
        raise ValueError(f"{name} must be {wanted}, got {value!r}")


def check_positive(name, value, allow_zero=False):
    """A number > 0 (>= 0 with ``allow_zero``), not NaN."""
    if not _is_number(value) or math.isnan(value) or value < 0 or (
        value == 0 and not allow_zero
    ):
        sign = "non-negative" if allow_zero else "positive"
        raise ValueError(f"{name} must be a {sign} number, got {value!r}")


def check_integer(name, value, low=None, high=None, what=""):
    """An integer in low..high (either end open when None); ``what`` says what it
    counts, for the message."""
    if (
        not isinstance(value, int)
        or isinstance(value, bool)
        or (low is not None and value < low)
        or (high is not None and value > high)
    ):
        bounds = {
            (True, True): f" in {low}..{high}",
            (True, False): f" >= {low}",
            (False, True): f" <= {high}",
            (False, False): "",
        }[(low is not None, high is not None)]
        raise ValueError(
            f"{name} must be {what or 'an integer'}{bounds}, got {value!r}"
        )


def check_positive_int(name, value):
    """An integer >= 1."""
    if not isinstance(value, int) or isinstance(value, bool) or value < 1:
        raise ValueError(f"{name} must be a positive integer, got {value!r}")


def check_probability(name, value, include_one=True):
    """A number in [0, 1] ([0, 1) without ``include_one``)."""
    if (
        not _is_number(value)
        or not 0 <= value <= 1
        or (value == 1 and not include_one)
    ):
        raise ValueError(
            f"{name} is a probability in [0, {'1]' if include_one else '1)'}, got"
            f" {value!r}"
        )


def check_flag(name, value):
    """True or False (not 1, 0 or a string)."""
    if not isinstance(value, bool):
        raise ValueError(f"{name} must be True or False, got {value!r}")


def with_overrides(settings, overrides, name=None):
    """The dataclass ``settings`` with the fields named in ``overrides`` changed (a
    clear error for a name it has not, calling the settings ``name``: their class's
    name by default)."""
    allowed = [f.name for f in fields(settings)]
    unknown = sorted(set(overrides) - set(allowed))
    if unknown:
        raise ValueError(
            f"{name or type(settings).__name__} has no setting {', '.join(unknown)};"
            f" its settings: {', '.join(allowed)}"
        )
    return replace(settings, **overrides)
