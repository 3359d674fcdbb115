"""A weights file of the ANN strategy (`fleet-mlp/1`, written by `fleet train`; those shipped
are in fleet/dispatching/weights/), read and checked without torch: `fleet run` refuses a
bad file before it starts anything, and only the process that scores with the networks pays
for importing torch (fleet/dispatching/mlp.py builds them from what is read here)."""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fleet.errors import UserError

HIDDEN = 12  # Section 3.3: "the number of hidden neurons is set to 12"
FORMAT = "fleet-mlp/1"


class WeightsError(UserError):
    """A weights file that cannot be used; the message says why."""


@dataclass(frozen=True)
class Weights:
    """One network per cluster, each as its parameters by name (torch's state dict names of
    `Linear(clusters, HIDDEN), Tanh, Linear(HIDDEN, 1)`), and the scaling of its input and
    output."""

    clusters: tuple[str, ...]
    input_scale: float
    nets: tuple[dict[str, np.ndarray], ...]
    target_mean: tuple[float, ...]
    target_scale: tuple[float, ...]
    layout: str = ""
    trained_on: int = 0  # samples


def net_shapes(inputs: int) -> dict[str, tuple[int, ...]]:
    """The parameters of one network and their shapes."""
    return {"0.weight": (HIDDEN, inputs), "0.bias": (HIDDEN,), "2.weight": (1, HIDDEN),
            "2.bias": (1,)}


def _finite(value: object) -> bool:
    """A number that fits a float and is neither infinite nor NaN."""
    if not isinstance(value, int | float):
        return False
    try:
        return math.isfinite(value)
    except OverflowError:  # an integer too large for a float
        return False


def read_weights(path: Path) -> Weights:
    """The weights in a file; a WeightsError names the file and what is wrong with it."""
    try:
        data = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError) as exc:
        raise WeightsError(f"{path}: cannot read: {exc}") from None
    except ValueError as exc:  # JSONDecodeError, or an integer literal too long
        raise WeightsError(f"{path}: not valid JSON: {exc}") from None
    except RecursionError:
        raise WeightsError(f"{path}: not valid JSON: nested too deep") from None
    return weights_from_json(data, str(path))


def weights_from_json(data: object, where: str) -> Weights:
    """The weights in a parsed file (`where` names it in every error)."""
    def bad(why: str) -> WeightsError:
        return WeightsError(f"{where}: {why}")

    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise bad(f"not a weights file (expected \"format\": \"{FORMAT}\")")
    clusters = data.get("clusters")
    if not isinstance(clusters, list) or not clusters or \
            not all(isinstance(c, str) for c in clusters):
        raise bad("'clusters' must be a list of cluster names")
    n = len(clusters)
    numbers = {}
    for key in ("target_mean", "target_scale"):
        values = data.get(key)
        if not isinstance(values, list) or len(values) != n or not all(
                _finite(v) for v in values):
            raise bad(f"'{key}' must be {n} finite numbers")
        numbers[key] = tuple(float(v) for v in values)
    scale = data.get("input_scale")
    if not _finite(scale) or not scale > 0:
        raise bad("'input_scale' must be a positive number")
    if data.get("hidden") != HIDDEN:
        raise bad(f"'hidden' must be {HIDDEN}")
    raw = data.get("nets")
    if not isinstance(raw, list) or len(raw) != n:
        raise bad(f"'nets' must hold {n} networks, one per cluster")
    nets = tuple(_network(state, net_shapes(n), lambda why, d=d: bad(
        f"network {d} ({clusters[d]}){why}")) for d, state in enumerate(raw))
    layout = data.get("layout", "")
    if not isinstance(layout, str):
        raise bad("'layout' must be a layout name")
    trained_on = data.get("trained_on", 0)
    if not isinstance(trained_on, int) or isinstance(trained_on, bool) or trained_on < 0:
        raise bad("'trained_on' must be a whole number of samples")
    return Weights(tuple(clusters), float(scale), nets, numbers["target_mean"],
                   numbers["target_scale"], layout, trained_on)


def _network(state: object, expected: dict[str, tuple[int, ...]],
             bad: Callable[[str], WeightsError]) -> dict[str, np.ndarray]:
    """One network's parameters: JSON numbers only (a string such as "1.5" is refused, not
    read as a number), each finite and of its shape."""
    if not isinstance(state, dict) or set(state) != set(expected):
        raise bad(f" must have {sorted(expected)}")
    arrays = {}
    for k, v in state.items():
        try:
            a = np.asarray(v)
        except ValueError as exc:  # uneven nesting
            raise bad(f": {k}: {exc}") from None
        if a.dtype.kind not in "iuf" or a.shape != expected[k] or \
                not bool(np.isfinite(a).all()):
            raise bad(f": {k} must be finite numbers of shape {list(expected[k])}")
        arrays[k] = a.astype(np.float64)
    return arrays
