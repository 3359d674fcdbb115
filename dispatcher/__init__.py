"""dispatcher package (filled in by later issues)."""
