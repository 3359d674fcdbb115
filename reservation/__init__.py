"""reservation package (filled in by later issues)."""
