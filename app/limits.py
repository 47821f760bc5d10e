"""Bounds on the work one request may ask for (422/413 naming the limit and its setting).

Every integer in a path or query has documented bounds (``INDEX_MAX`` for offsets and
indices); the rest are settings (``app.settings``, ``SCENGEN_*``) so a deployment can move
them: the number and length of constraints, the size of a posted scenario (objects, time
steps), the options of a model fit, the size of a JSON body. Routes call the ``check_*``
functions before any work starts.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

from app.errors import InvalidInput
from app.settings import Settings

#: largest offset / index accepted in a path or query (a 32-bit signed integer); larger
#: values are a 422, not an overflow deep in the database driver
INDEX_MAX = 2**31 - 1


def _env(setting: str) -> str:
    return f"SCENGEN_{setting.upper()}"


def check_constraints(texts: Sequence[str], settings: Settings,
                      field: str = "body.constraints") -> None:
    """At most ``constraints_limit`` constraints of at most ``constraint_length_limit``
    characters each."""
    limit = settings.constraints_limit
    if len(texts) > limit:
        raise InvalidInput(f"{len(texts)} constraints; the limit is {limit} "
                           f"({_env('constraints_limit')})", field=field)
    length = settings.constraint_length_limit
    for i, text in enumerate(texts):
        if len(text) > length:
            raise InvalidInput(f"constraint {i} has {len(text)} characters; the limit is "
                               f"{length} ({_env('constraint_length_limit')})",
                               field=f"{field}.{i}")


def check_posted_scenario(data: Any, settings: Settings) -> None:
    """A posted concrete scenario has at most ``risk_objects_limit`` objects and
    ``risk_steps_limit`` time steps (the scoring cost grows with both)."""
    if not isinstance(data, Mapping):
        return  # the scenario parser names what is wrong
    objects = data.get("objects")
    if (isinstance(objects, Sequence | Mapping) and not isinstance(objects, str)
            and len(objects) > settings.risk_objects_limit):
        raise InvalidInput(f"{len(objects)} objects; the limit is "
                           f"{settings.risk_objects_limit} "
                           f"({_env('risk_objects_limit')})", field="body.objects")
    steps = data.get("t")
    if (isinstance(steps, Sequence) and not isinstance(steps, str)
            and len(steps) > settings.risk_steps_limit):
        raise InvalidInput(f"{len(steps)} time steps; the limit is "
                           f"{settings.risk_steps_limit} ({_env('risk_steps_limit')})",
                           field="body.t")


#: integer options of a model fit -> (smallest allowed, setting holding the largest)
MODEL_INT_OPTIONS: dict[str, tuple[int, str]] = {
    "n_init": (1, "model_n_init_limit"),
    "max_iter": (1, "model_max_iter_limit"),
    "cv_folds": (2, "model_cv_folds_limit"),
    "n_report_samples": (100, "model_report_samples_limit"),
}


def _as_int(value: Any, field: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise InvalidInput(f"expected an integer, got {str(value)[:40]!r}", field=field)
    if isinstance(value, float) and not (math.isfinite(value) and value.is_integer()):
        raise InvalidInput(f"expected an integer, got {value!r}", field=field)
    return int(value)


def check_model_options(options: Mapping[str, Any], settings: Settings,
                        field: str = "body.options") -> None:
    """Bounds on the options of a model fit that set its cost (``MODEL_INT_OPTIONS``,
    ``k_range`` against ``model_k_limit``); other options are checked by the model."""
    for name, (low, setting) in MODEL_INT_OPTIONS.items():
        if name not in options:
            continue
        value = _as_int(options[name], f"{field}.{name}")
        high = int(getattr(settings, setting))
        if not low <= value <= high:
            raise InvalidInput(f"{name} = {value} is outside {low}..{high} (the upper limit "
                               f"is {_env(setting)})", field=f"{field}.{name}")
    if "k_range" in options:
        k_range = options["k_range"]
        where = f"{field}.k_range"
        if not isinstance(k_range, Sequence) or isinstance(k_range, str) or len(k_range) != 2:
            raise InvalidInput("k_range: expected [min, max]", field=where)
        k_lo, k_hi = (_as_int(k, where) for k in k_range)
        limit = settings.model_k_limit
        if not 1 <= k_lo <= k_hi <= limit:
            raise InvalidInput(f"k_range = [{k_lo}, {k_hi}]: need 1 <= min <= max <= "
                               f"{limit} ({_env('model_k_limit')})", field=where)
    for name in ("features", "transforms", "fixed"):
        entries = options.get(name)
        if isinstance(entries, Sequence | Mapping) and len(entries) > 64:
            raise InvalidInput(f"{name}: {len(entries)} entries; at most 64",
                               field=f"{field}.{name}")
