"""The recorder process (`fleet recorder`, `python -m recorder`) and its live Foxglove view; the
MCAP format and what reads it are in the core (fleet/recording, fleet/analysis, fleet/views)."""
