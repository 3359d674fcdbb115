"""Fault scenarios shipped with fleet (docs/faults.md)."""
