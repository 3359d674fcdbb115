"""Where the ANN strategy gets its networks: a weights file, or the ones shipped for a
built-in layout (trained with `fleet train`, see docs/dispatching.md)."""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from fleet.dispatching.mlp import ClusterMLPs, WeightsError
from fleet.world.layout import Layout


def shipped_weights(layout_name: str) -> Path | None:
    path = Path(str(resources.files("fleet.dispatching.weights").joinpath(f"{layout_name}.json")))
    return path if path.is_file() else None


def load_scorer(layout: Layout, weights: Path | None = None) -> ClusterMLPs:
    """The trained networks for `layout`; they must score exactly its clusters."""
    path = weights or shipped_weights(layout.name)
    if path is None:
        raise WeightsError(f"no trained weights ship for layout {layout.name!r}: train them "
                           f"with `fleet train --layout ...` and pass --weights FILE")
    mlps = ClusterMLPs.load(path)
    names = tuple(c.name for c in layout.clusters)
    if mlps.clusters != names:
        raise WeightsError(f"{path}: trained for clusters {', '.join(mlps.clusters)}, but "
                           f"layout {layout.name} has {', '.join(names)}")
    return mlps
