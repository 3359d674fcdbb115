"""The MLP correction: Levenberg-Marquardt, weights files, training cycles, and that trained
weights change the ANN strategy's choices."""

import json
import subprocess
import sys

import pytest
import torch

from fleet.dispatching.decision import Strategy
from fleet.dispatching.mlp import ClusterMLPs, lm_fit, make_net
from fleet.dispatching.scorer import load_scorer
from fleet.dispatching.weights_file import WeightsError
from fleet.mission.engine import EngineOptions, run_mission
from fleet.mission.spec import Mission
from fleet.mission.training import train
from fleet.world.layout_file import load_layout


def test_lm_step_decreases_the_loss_on_a_fixed_problem():
    torch.manual_seed(7)
    x = torch.linspace(-1, 1, 40, dtype=torch.float64).reshape(-1, 1).repeat(1, 2)
    y = torch.sin(3 * x[:, 0]) + 0.5 * x[:, 1] ** 2
    net = make_net(2)
    report = lm_fit(net, x, y, steps=30)
    assert report.losses[0] < report.initial
    assert all(b <= a for a, b in zip(report.losses, report.losses[1:], strict=False))
    assert report.losses[-1] < 0.01 * report.initial
    with torch.no_grad():
        fitted = net(x).reshape(-1)
    assert float(((fitted - y) ** 2).mean()) == pytest.approx(report.losses[-1])


def test_weights_round_trip(tmp_path):
    mlps = ClusterMLPs.fresh(("a", "b"), 12, seed=3, layout="small")
    path = tmp_path / "w.json"
    mlps.save(path)
    again = ClusterMLPs.load(path)
    assert again([3.0, -5.0]) == mlps([3.0, -5.0])
    assert again.clusters == ("a", "b")


@pytest.mark.parametrize("edit, message", [
    (lambda d: d.update(format="other"), "not a weights file"),
    (lambda d: d.update(clusters=["a"]), "'target_mean' must be 1 finite numbers"),
    (lambda d: d["nets"][1].pop("0.weight"), r"network 1 \(b\) must have"),
    (lambda d: d["nets"][0]["2.bias"].__setitem__(0, "x"), r"network 0 \(a\)"),
    (lambda d: d["target_scale"].__setitem__(0, float("nan")), "finite numbers"),
])
def test_bad_weights_are_named(tmp_path, edit, message):
    data = ClusterMLPs.fresh(("a", "b"), 12, seed=3).to_json()
    edit(data)
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(data))
    with pytest.raises(WeightsError, match=message):
        ClusterMLPs.load(path)


def test_weights_are_checked_without_torch_and_score_as_read(tmp_path):
    """fleet run refuses bad weights before it starts anything without importing torch (a
    second of start-up); the dispatcher's networks are built from exactly what was read."""
    path = tmp_path / "w.json"
    written = ClusterMLPs.fresh(("a", "b"), 12, seed=3)
    written.save(path)
    checked = subprocess.run(
        [sys.executable, "-c", "import sys; from pathlib import Path; "
         "from fleet.dispatching.scorer import layout_weights; "
         "from fleet.world.layout_file import load_layout; "
         f"read = layout_weights(load_layout('small'), Path({str(path)!r})); "
         "print(read.clusters, 'torch' in sys.modules)"],
        capture_output=True, text=True, check=True)
    assert checked.stdout.split() == ["('a',", "'b')", "False"]
    again = load_scorer(load_layout("small"), path)
    assert again([3.0, 4.0]) == written([3.0, 4.0])
    assert again.to_json() == json.loads(path.read_text())


def test_weights_for_another_layout_are_refused(tmp_path):
    path = tmp_path / "w.json"
    ClusterMLPs.fresh(("x", "y"), 12, seed=1).save(path)
    with pytest.raises(WeightsError, match="trained for clusters x, y, but layout small has a, b"):
        load_scorer(load_layout("small"), path)


def test_training_is_reproducible_and_refits_every_cycle():
    small = load_layout("small")
    a, reports = train(small, cycles=2, seed=5, lm_steps=10)
    b, _ = train(small, cycles=2, seed=5, lm_steps=10)
    assert a.to_json() == b.to_json()
    assert [r.strategy for r in reports] == ["comprehensive", "ann"]
    assert reports[1].samples > reports[0].samples > 0
    assert all(r.loss_after < r.loss_before for r in reports)


def test_shipped_weights_change_the_ann_choices():
    small = load_layout("small")
    ann = run_mission(Mission(layout="small", strategy=Strategy.ANN),
                      EngineOptions(mlp=load_scorer(small)), small)
    comprehensive = run_mission(Mission(layout="small", strategy=Strategy.COMPREHENSIVE),
                                None, small)
    picks = [(s.vehicle, s.target) for s in ann.subtasks]
    assert picks != [(s.vehicle, s.target) for s in comprehensive.subtasks]


def test_saved_weights_do_not_change_when_training_goes_on():
    mlps = ClusterMLPs.fresh(("a", "b"), 12, seed=3)
    saved = mlps.to_json()
    frozen = json.dumps(saved)
    x = [((1.0, 2.0), 0, 5.0), ((2.0, 1.0), 0, 7.0), ((0.0, 3.0), 1, 1.0), ((3.0, 0.0), 1, 2.0)]
    mlps.fit(x, steps=3)
    assert json.dumps(saved) == frozen


def test_the_networks_written_are_the_last_fit_whatever_the_cycles_scored():
    """The rule is fixed before any mission judges the networks: on `small`, seed 0, cycle 2
    (with the networks of the first fit) fills sooner than cycle 3, and the networks written
    are still those of the third fit, on every sample of the three cycles."""
    small = load_layout("small")
    three, reports = train(small, cycles=3, seed=0, lm_steps=20)
    first_fit, _ = train(small, cycles=1, seed=0, lm_steps=20)  # what cycle 2 filled with
    assert reports[1].end_time < reports[2].end_time  # a best-cycle rule would keep those
    assert three.trained_on == reports[-1].samples > reports[1].samples
    assert three.to_json()["nets"] != first_fit.to_json()["nets"]
    again = run_mission(Mission(layout="small", strategy=Strategy.ANN),
                        EngineOptions(mlp=first_fit), small)
    assert again.end_time == reports[1].end_time  # cycle 2's fill, reproduced
