"""The MLP correction of seed 000 (Section 3.3, Equations 5 to 8), in torch.

One network per shelf cluster: the inputs are the vector U of Equation (7) (one element per
cluster), one hidden layer of 12 tanh neurons (f_j), and a linear output (F), predicting
J_d,est for its cluster. Torch has no Levenberg-Marquardt optimiser, so `lm_fit` writes the
damped Gauss-Newton step itself with a Jacobian from `torch.func.jacrev`; with 97 parameters
per network the normal equations are tiny. Everything is float64 and seeded, so training is
reproducible.

Inputs are divided by the largest cluster size and targets standardised (mean, scale kept with
the weights), so the same damping works on every layout.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import torch
from torch.func import functional_call, jacrev

from fleet.dispatching.weights_file import (
    FORMAT,
    HIDDEN,
    Weights,
    read_weights,
)


def one_thread() -> None:
    """Let torch use one core: for a process among others that each have theirs."""
    torch.set_num_threads(1)


def make_net(inputs: int, hidden: int = HIDDEN) -> torch.nn.Sequential:
    return torch.nn.Sequential(torch.nn.Linear(inputs, hidden), torch.nn.Tanh(),
                               torch.nn.Linear(hidden, 1)).double()


@dataclass
class LMReport:
    initial: float = 0.0  # mean squared error before the first step
    losses: list[float] = field(default_factory=list)  # after each step
    damping: float = 0.0


def lm_fit(net: torch.nn.Module, x: torch.Tensor, y: torch.Tensor, steps: int = 50,
           damping: float = 1e-2) -> LMReport:
    """Levenberg-Marquardt on the mean squared error: solve (J'J + mu diag(J'J) + mu I) d =
    -J'r, keep the step if the loss falls (and trust the model more: mu / 10), otherwise
    undo it and damp harder (mu * 10)."""
    names = [n for n, _ in net.named_parameters()]
    shapes = [p.shape for _, p in net.named_parameters()]
    sizes = [p.numel() for _, p in net.named_parameters()]

    def unflatten(theta: torch.Tensor) -> dict[str, torch.Tensor]:
        parts = torch.split(theta, sizes)
        return {n: t.reshape(s) for n, t, s in zip(names, parts, shapes, strict=True)}

    def residual(theta: torch.Tensor) -> torch.Tensor:
        return functional_call(net, unflatten(theta), (x,)).reshape(-1) - y

    theta = torch.cat([p.detach().reshape(-1) for p in net.parameters()])
    report = LMReport()
    with torch.no_grad():
        r = residual(theta)
    loss = report.initial = float(r @ r) / len(y)
    mu = damping
    eye = torch.eye(len(theta), dtype=theta.dtype)
    for _ in range(steps):
        jac = jacrev(residual)(theta)
        jtj = jac.T @ jac
        grad = jac.T @ r
        while True:
            a = jtj + mu * (torch.diag(torch.diagonal(jtj)) + eye)
            step = torch.linalg.solve(a, -grad)
            candidate = theta + step
            with torch.no_grad():
                r_new = residual(candidate)
            new_loss = float(r_new @ r_new) / len(y)
            if new_loss < loss:
                theta, r, loss = candidate, r_new, new_loss
                mu = max(mu / 10, 1e-12)
                break
            mu *= 10
            if mu > 1e12:
                break
        report.losses.append(loss)
        if mu > 1e12 or loss < 1e-12:
            break
    report.damping = mu
    with torch.no_grad():
        for n, value in unflatten(theta).items():
            dict(net.named_parameters())[n].copy_(value)
    return report


@dataclass
class ClusterMLPs:
    """The six (one per cluster) networks of Equation (8) and their scaling."""

    clusters: tuple[str, ...]
    input_scale: float
    nets: list[torch.nn.Sequential]
    target_mean: list[float]
    target_scale: list[float]
    layout: str = ""
    trained_on: int = 0  # samples

    @classmethod
    def fresh(cls, clusters: tuple[str, ...], input_scale: float, seed: int,
              layout: str = "") -> ClusterMLPs:
        torch.manual_seed(seed)
        nets = [make_net(len(clusters)) for _ in clusters]
        n = len(clusters)
        return cls(tuple(clusters), float(input_scale), nets, [0.0] * n, [1.0] * n, layout)

    def __call__(self, u: list[float]) -> list[float]:
        """J_hat_d,est for every cluster, given U."""
        x = torch.tensor([v / self.input_scale for v in u], dtype=torch.float64)
        with torch.no_grad():
            out = [float(net(x)[0]) for net in self.nets]
        return [o * s + m for o, s, m in zip(out, self.target_scale, self.target_mean,
                                             strict=True)]

    def fit(self, samples: list[tuple[tuple[float, ...], int, float]], steps: int = 50
            ) -> dict[str, LMReport]:
        """Train each cluster's network on its samples (U, cluster index, target J)."""
        reports = {}
        for d, name in enumerate(self.clusters):
            mine = [(u, t) for u, k, t in samples if k == d]
            if len(mine) < 2:
                continue
            targets = torch.tensor([t for _, t in mine], dtype=torch.float64)
            mean = float(targets.mean())
            scale = float(targets.std()) or 1.0
            self.target_mean[d], self.target_scale[d] = mean, scale
            x = torch.tensor([[v / self.input_scale for v in u] for u, _ in mine],
                             dtype=torch.float64)
            reports[name] = lm_fit(self.nets[d], x, (targets - mean) / scale, steps)
        self.trained_on = len(samples)
        return reports

    # -- files -------------------------------------------------------------------------------
    def to_json(self) -> dict:
        return {
            "format": FORMAT, "layout": self.layout, "clusters": list(self.clusters),
            "hidden": HIDDEN, "input_scale": self.input_scale, "trained_on": self.trained_on,
            "target_mean": list(self.target_mean), "target_scale": list(self.target_scale),
            "nets": [{n: p.detach().tolist() for n, p in net.state_dict().items()}
                     for net in self.nets],
        }

    def save(self, path: Path) -> None:
        path.write_text(json.dumps(self.to_json(), indent=1))

    @classmethod
    def from_weights(cls, weights: Weights) -> ClusterMLPs:
        nets = []
        for state in weights.nets:
            net = make_net(len(weights.clusters))
            net.load_state_dict({k: torch.from_numpy(a) for k, a in state.items()})
            nets.append(net)
        return cls(weights.clusters, weights.input_scale, nets, list(weights.target_mean),
                   list(weights.target_scale), weights.layout, weights.trained_on)

    @classmethod
    def load(cls, path: Path) -> ClusterMLPs:
        return cls.from_weights(read_weights(path))
