"""Where the ANN strategy gets its networks: a weights file, or the ones shipped for a
built-in layout (trained with `fleet train`, see docs/dispatching.md)."""

from __future__ import annotations

from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING

from fleet.dispatching.weights_file import Weights, WeightsError, read_weights
from fleet.world.layout import Layout

if TYPE_CHECKING:  # torch is imported only where the networks score
    from fleet.dispatching.mlp import ClusterMLPs


def shipped_weights(layout_name: str) -> Path | None:
    path = Path(str(resources.files("fleet.dispatching.weights").joinpath(
        f"{layout_name}.json")))
    return path if path.is_file() else None


def layout_weights(layout: Layout, weights: Path | None = None) -> Weights:
    """The trained networks' weights for `layout`, read and checked (no torch): they must
    score exactly its clusters."""
    path = weights or shipped_weights(layout.name)
    if path is None:
        raise WeightsError(f"no trained weights ship for layout {layout.name!r}: train them "
                           f"with `fleet train --layout ...` and pass --weights FILE")
    read = read_weights(path)
    names = tuple(c.name for c in layout.clusters)
    if read.clusters != names:
        raise WeightsError(f"{path}: trained for clusters {', '.join(read.clusters)}, but "
                           f"layout {layout.name} has {', '.join(names)}")
    return read


def load_scorer(layout: Layout, weights: Path | None = None) -> ClusterMLPs:
    """The trained networks for `layout`."""
    from fleet.dispatching.mlp import ClusterMLPs

    return ClusterMLPs.from_weights(layout_weights(layout, weights))
