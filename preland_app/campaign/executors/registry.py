"""Executors by name. Built-in ones are import paths, so an executor's own package (Ray) is imported only
when it is chosen; `register_executor` adds another (a Dask executor would be one more entry)."""

from __future__ import annotations

import importlib
from collections.abc import Callable

from .base import ExecutorError, ExecutorOptions, TrialExecutor

ExecutorFactory = Callable[[ExecutorOptions], TrialExecutor]

_EXECUTORS: dict[str, str | ExecutorFactory] = {
    "local": "preland_app.campaign.executors.local:LocalExecutor",
    "ray": "preland_app.campaign.executors.ray:RayExecutor",
}


def register_executor(name: str, factory: ExecutorFactory) -> None:
    """Make `factory(options)` available as executor `name` (replacing one of that name)."""
    _EXECUTORS[name] = factory


def executor_names() -> list[str]:
    return sorted(_EXECUTORS)


def executor_factory(name: str) -> ExecutorFactory:
    """The factory of executor `name`; ExecutorError naming the known ones when there is none."""
    entry = _EXECUTORS.get(name)
    if entry is None:
        raise ExecutorError(f"unknown executor {name!r} (known: {', '.join(executor_names())})")
    if isinstance(entry, str):
        module, _, attribute = entry.partition(":")
        entry = getattr(importlib.import_module(module), attribute)
    return entry


def create_executor(name: str, options: ExecutorOptions) -> TrialExecutor:
    return executor_factory(name)(options)
