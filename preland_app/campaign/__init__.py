"""Campaigns: spec files, repeated trials in worker processes, a durable SQLite store, reports."""
