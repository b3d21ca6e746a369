"""Campaigns: spec files, repeated trials on an executor (local processes, Ray), a durable SQLite store, reports."""
