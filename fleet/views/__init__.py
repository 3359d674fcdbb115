"""Pictures of a run: the matplotlib drawings and plots, and the Foxglove scene (matplotlib and
foxglove live here and nowhere else in the core)."""
