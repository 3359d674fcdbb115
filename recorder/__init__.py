"""recorder package (filled in by later issues)."""
