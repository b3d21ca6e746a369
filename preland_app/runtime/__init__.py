"""Runtimes: where a trial flies (embedded simulator now; ArduPilot SITL and field over MAVLink)."""
