"""Land modes from outside preland: import paths, entry points, and keyword options checked at load time.

A land mode is named by a short name (a built-in, or one that an installed
package registers under the entry-point group `preland.land_modes`) or by an
import path `package.module:ClassName`. Either way it is a callable (normally a
class) that takes keyword options and returns a `LandStrategy`. The options
come from a mission's `land.params` or a campaign scenario's `land_params`;
they are checked against the callable's signature and annotations when the
file loads (unknown or missing keywords, wrong types), and the strategy is
made once then, so a constructor that refuses its options is reported before
any trial flies.
"""

from __future__ import annotations

import importlib
import importlib.metadata
import inspect
import re
import traceback
import typing
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from ..config.loader import convert
from ..errors import PrelandError, SpecError, SpecValueError
from .base import LandStrategy, ScoringReference

ENTRY_POINT_GROUP = "preland.land_modes"
_IMPORT_PATH = re.compile(r"[A-Za-z_]\w*(\.[A-Za-z_]\w*)*:[A-Za-z_]\w*(\.[A-Za-z_]\w*)*")
# What a LandStrategy must have, and what each must be.
_CONTRACT: dict[str, tuple[Callable[[Any], bool], str]] = {
    "name": (lambda v: isinstance(v, str) and bool(v), "a non-empty string"),
    "scoring_reference": (lambda v: isinstance(v, ScoringReference),
                          "a preland_app.landing.ScoringReference (PAD or TAKEOFF)"),
    "uses_irlock": (lambda v: isinstance(v, bool), "true or false"),
    "uses_marker": (lambda v: isinstance(v, bool), "true or false"),
    "land": (inspect.iscoroutinefunction, "an async method land(context) -> LandingReport"),
}


class LandModeError(PrelandError):
    """A land mode cannot be found, imported or made; the message is one line saying why."""


def is_import_path(name: str) -> bool:
    """True when `name` names a land mode by import path (`package.module:ClassName`)."""
    return ":" in name


def where(error: BaseException) -> str:
    """` (at file.py:LINE)`: the innermost frame an exception came from, or ''."""
    frames = traceback.extract_tb(error.__traceback__) if error.__traceback__ else []
    return f" (at {Path(frames[-1].filename).name}:{frames[-1].lineno})" if frames else ""


def load_object(target: str) -> Any:
    """The object an import path `package.module:Name` names; raises LandModeError saying why not."""
    if not _IMPORT_PATH.fullmatch(target):
        raise LandModeError(f"{target!r} is not an import path (expected package.module:ClassName)")
    module_name, _, attribute = target.partition(":")
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as error:
        missing = error.name or module_name
        if module_name == missing or module_name.startswith(missing + "."):
            raise LandModeError(f"cannot import {module_name!r}: no module named {missing!r} "
                                "(is its folder on PYTHONPATH, or its package installed?)") from None
        raise LandModeError(f"cannot import {module_name!r}: {type(error).__name__}: {error}{where(error)}") from None
    except Exception as error:  # the plugin's own module failed while importing
        raise LandModeError(f"cannot import {module_name!r}: {type(error).__name__}: {error}{where(error)}") from None
    found: Any = module
    for part in attribute.split("."):
        try:
            found = getattr(found, part)
        except AttributeError:
            raise LandModeError(f"module {module_name!r} has no {attribute!r}") from None
    if not callable(found):
        raise LandModeError(f"{target!r} is a {type(found).__name__}, not a class")
    return found


def installed_entry_points() -> dict[str, importlib.metadata.EntryPoint]:
    """Land modes that installed packages register under `preland.land_modes`, by name (first one wins)."""
    found: dict[str, importlib.metadata.EntryPoint] = {}
    for entry_point in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP):
        found.setdefault(entry_point.name, entry_point)
    return found


def entry_point_origin(entry_point: importlib.metadata.EntryPoint) -> str:
    """The distribution that registers an entry point, with its version (`preland-proportional 0.1.0`)."""
    dist = getattr(entry_point, "dist", None)
    if dist is None:
        return "entry point"
    return f"{dist.metadata['Name'] or dist.name} {dist.version}"


def _hints(factory: Callable[..., Any]) -> dict[str, Any]:
    """The annotations of the factory's keyword options, resolved; {} where they cannot be."""
    function = factory.__init__ if inspect.isclass(factory) else factory
    try:
        return typing.get_type_hints(function)
    except Exception:  # unresolvable string annotations: check what can be checked
        raw = getattr(function, "__annotations__", {}) or {}
        return {name: hint for name, hint in raw.items() if not isinstance(hint, str)}


def _convert_option(value: Any, hint: Any, *, field: str) -> Any:
    try:
        return convert(value, hint, path="", field=field)
    except SpecError as error:
        if not error.problem.startswith("unsupported type"):
            raise SpecValueError(error.field, error.problem) from None
    # An annotation the spec loader does not know (a class of the plugin's own, a Callable...).
    if isinstance(hint, type) and not isinstance(value, hint):
        raise SpecValueError(field, f"expected {hint.__name__}, got {value!r}")
    return value


def check_options(factory: Callable[..., Any], options: Mapping[str, Any], *, describe: str) -> dict[str, Any]:
    """`options` checked against the factory's keyword parameters and converted to their annotated types
    (as spec files are: an integer where a number is wanted, a list for a tuple, a mapping for a
    dataclass). Raises SpecValueError at `params.KEY`."""
    try:
        signature = inspect.signature(factory)
    except (TypeError, ValueError):  # no signature to check against (a builtin): pass the options as they are
        return dict(options)
    parameters = signature.parameters.values()
    any_keyword = any(p.kind is inspect.Parameter.VAR_KEYWORD for p in parameters)
    named = {p.name: p for p in parameters
             if p.kind in (inspect.Parameter.POSITIONAL_OR_KEYWORD, inspect.Parameter.KEYWORD_ONLY)}
    for key in options:
        if key not in named and not any_keyword:
            known = ", ".join(named) or "none"
            raise SpecValueError(f"params.{key}", f"unknown keyword: {describe} takes {known}")
    for name, parameter in named.items():
        if parameter.default is inspect.Parameter.empty and name not in options:
            raise SpecValueError(f"params.{name}", f"missing: {describe} needs this keyword")
    for parameter in parameters:
        if parameter.kind is inspect.Parameter.POSITIONAL_ONLY and parameter.default is inspect.Parameter.empty:
            raise SpecValueError("params", f"{describe} needs a positional argument {parameter.name!r}; "
                                           "a land mode takes keyword options only")
    hints = _hints(factory)
    return {key: _convert_option(value, hints.get(key, Any), field=f"params.{key}") for key, value in options.items()}


def check_strategy(strategy: Any, *, describe: str) -> LandStrategy:
    """`strategy` if it satisfies the LandStrategy contract; raises LandModeError naming what is wrong."""
    for attribute, (valid, expected) in _CONTRACT.items():
        if not hasattr(strategy, attribute):
            raise LandModeError(f"{describe} is not a LandStrategy: it has no {attribute!r} ({expected})")
        if not valid(getattr(strategy, attribute)):
            raise LandModeError(f"{describe} is not a LandStrategy: {attribute!r} must be {expected}, "
                                f"got {getattr(strategy, attribute)!r}")
    return strategy


def make_strategy(factory: Callable[..., Any], options: Mapping[str, Any], *, describe: str) -> LandStrategy:
    """A fresh strategy from checked options; the factory's own refusal becomes SpecValueError at `params`."""
    converted = check_options(factory, options, describe=describe)
    try:
        strategy = factory(**converted)
    except Exception as error:
        raise SpecValueError("params", f"{describe} refused its options: {type(error).__name__}: {error}"
                                       f"{where(error)}") from None
    return check_strategy(strategy, describe=describe)


def precision_sensor_of(strategy: LandStrategy) -> str | None:
    """The sensor a strategy lands on, from what it uses: fused, irlock, marker, or None (GPS only)."""
    return {(True, True): "fused", (True, False): "irlock", (False, True): "marker", (False, False): None}[
        (bool(strategy.uses_irlock), bool(strategy.uses_marker))]
