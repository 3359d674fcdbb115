"""Core library of the forklift fleet emulator: pure planning code, no I/O."""

__version__ = "0.1.0"
