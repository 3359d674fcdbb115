"""The recorder process (`fleet recorder`) and its live Foxglove view; the MCAP format and
what reads it are in fleet/ (recording, analysis, safety, scene)."""
