"""Field trials: preflight checks, pilot takeover, geofence."""
