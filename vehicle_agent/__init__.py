"""vehicle_agent package (filled in by later issues)."""
