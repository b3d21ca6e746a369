"""Where a campaign's trials run: one small interface (`base.TrialExecutor`), executors found by name."""

from .base import ExecutorError, ExecutorOptions, TrialExecutor
from .registry import create_executor, executor_factory, executor_names, register_executor

__all__ = ["ExecutorError", "ExecutorOptions", "TrialExecutor", "create_executor", "executor_factory",
           "executor_names", "register_executor"]
