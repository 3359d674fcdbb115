"""Fault scenarios as data: what loads, what is refused (naming the fault and the field), and
the `fleet faults` command."""

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fleet.cli import main
from fleet.mission.faults import (
    FaultKind,
    ScenarioError,
    builtin_scenarios,
    check_against,
    load_scenario,
    parse_scenario,
)
from fleet.mission.freeze import VehicleDown, VehicleUp, ZoneClosure, scheduled_at
from fleet.world.layout_file import load_layout


def test_every_shipped_scenario_loads_and_fits_paper_with_four_forklifts():
    names = builtin_scenarios()
    kinds = {f.kind for name in names for f in load_scenario(name).faults}
    # one scenario at least per kind a run on one host has (a host cut needs several hosts:
    # tests/test_multi_host.py)
    one_host = set(FaultKind) - {FaultKind.CUT_HOST}
    assert kinds == one_host
    mixed = load_scenario("mixed")
    assert {f.kind for f in mixed.faults} == one_host
    for name in names:
        check_against(load_scenario(name), load_layout("paper"), 4)


def test_a_scenario_says_when_the_clock_must_stop_and_what_happens_there():
    scenario = parse_scenario("""
        [[fault]]
        kind = "kill_vehicle"
        at = 10
        vehicle = 2
        duration = 5
        [[fault]]
        kind = "close_zone"
        at = 12
        duration = 3
        cells = ["1,1..2,1", "4,4"]
        [[fault]]
        kind = "vehicle_breakdown"
        at = 15
        vehicle = 1
        [[fault]]
        kind = "slow_planner"
        at = 1
        vehicle = 1
        duration = 2
        factor = 4
    """, "test")
    assert scenario.instants() == [1, 3, 10, 12, 15]  # a breakdown for good never ends
    assert scheduled_at(scenario, 10) == [VehicleDown(2, 10, "agent killed")]
    assert scheduled_at(scenario, 15) == [VehicleUp(2, 15), VehicleDown(1, 15, "breakdown")]
    assert scheduled_at(scenario, 12) == [
        ZoneClosure(frozenset({(1, 1), (2, 1), (4, 4)}), 12, 15)]
    assert scheduled_at(scenario, 1) == []  # a slow planner changes no sim time
    assert scenario.faults[2].until == math.inf


@pytest.mark.parametrize("text, says", [
    ("[[fault]]\nkind = 'melt'\nat = 1", "fault 1: kind 'melt' is not one of"),
    ("[[fault]]\nkind = 'kill_vehicle'\nat = 1", "fault 1 (kill_vehicle): missing field "
     "'vehicle'"),
    ("[[fault]]\nkind = 'kill_vehicle'\nvehicle = 1", "missing field 'at'"),
    ("[[fault]]\nkind = 'kill_vehicle'\nat = 1\nvehicle = 1\nspeed = 3",
     "unknown field 'speed'"),
    ("[[fault]]\nkind = 'kill_vehicle'\nat = -1\nvehicle = 1", "at must be at least 0"),
    ("[[fault]]\nkind = 'kill_vehicle'\nat = 1\nvehicle = 0", "vehicle must be a forklift"),
    ("[[fault]]\nkind = 'stall_vehicle'\nat = 1\nvehicle = 1\nduration = 0",
     "duration must be positive"),
    ("[[fault]]\nkind = 'slow_planner'\nat = 1\nvehicle = 1\nduration = 5\nfactor = 0.5",
     "factor must be between 1 and 1000"),
    ("[[fault]]\nkind = 'kill_service'\nat = 1\nservice = 'router'",
     "service 'router' is not one of"),
    ("[[fault]]\nkind = 'kill_service'\nat = 1\nservice = 'reservation'\ndowntime = 20",
     "downtime must be at most 10 wall seconds"),
    ("[[fault]]\nkind = 'close_zone'\nat = 1\nduration = 5\ncells = '1;2'",
     "is not a cell"),
    ("[[fault]]\nkind = 'close_zone'\nat = 1\nduration = 5\ncells = 3", "cells must be"),
    ("faults = 1", "unknown key 'faults'"),
    ("[[fault]\n", "not valid TOML"),
    ("[[fault]]\nkind = 'stall_vehicle'\nat = 1\nvehicle = 2\nduration = 10\n"
     "[[fault]]\nkind = 'kill_vehicle'\nat = 5\nvehicle = 2",
     "fault 2 (kill_vehicle of forklift 2 at 5 s) starts before fault 1"),
])
def test_a_bad_scenario_is_refused_naming_the_fault_and_the_field(text, says):
    with pytest.raises(ScenarioError, match=None) as caught:
        parse_scenario(text, "bad.toml")
    assert says in str(caught.value) and str(caught.value).startswith("bad.toml")


def test_a_scenario_is_checked_against_the_run():
    paper = load_layout("paper")
    with pytest.raises(ScenarioError, match="the run has forklifts 1 to 1"):
        check_against(load_scenario("kill_vehicle"), paper, 1)
    off = parse_scenario("[[fault]]\nkind = 'close_zone'\nat = 1\nduration = 2\n"
                         "cells = '17,11..18,11'", "off.toml")
    with pytest.raises(ScenarioError, match=r"cell \(18, 11\) is off the 18x12 map"):
        check_against(off, paper, 4)


@settings(max_examples=300, deadline=None, derandomize=True)
@given(st.text(max_size=300))
def test_any_text_is_a_scenario_or_a_clear_refusal(text):
    try:
        scenario = parse_scenario(text, "fuzz.toml")
    except ScenarioError as exc:
        assert str(exc).startswith("fuzz.toml")
    else:
        assert all(f.at >= 0 for f in scenario.faults)


VALUES = st.one_of(st.integers(-5, 10**7), st.floats(allow_nan=True), st.text(max_size=8),
                   st.booleans(), st.lists(st.integers(0, 3), max_size=3))


@settings(max_examples=300, deadline=None, derandomize=True)
@given(st.sampled_from(list(FaultKind)),
       st.dictionaries(st.sampled_from(["at", "vehicle", "duration", "factor", "service",
                                        "downtime", "cells", "other"]), VALUES, max_size=6))
def test_any_fault_table_is_a_fault_or_a_refusal_naming_it(kind, fields):
    import tomli_w

    try:
        text = tomli_w.dumps({"fault": [{"kind": kind.value, **fields}]})
    except (TypeError, ValueError):
        return  # not expressible in TOML (NaN is, but some floats' text is not)
    try:
        scenario = parse_scenario(text, "fuzz.toml")
    except ScenarioError as exc:
        assert "fuzz.toml: fault 1" in str(exc)
    else:
        (fault,) = scenario.faults
        assert fault.kind is kind and math.isfinite(fault.at) and fault.at >= 0


def test_fleet_faults_list_show_and_check(capsys):
    assert main(["faults", "list"]) == 0
    out = capsys.readouterr().out
    assert all(kind.value in out for kind in FaultKind) and "mixed" in out
    assert main(["faults", "show", "cut_link"]) == 0
    assert 'kind = "cut_link"' in capsys.readouterr().out
    assert main(["faults", "check", "mixed"]) == 0
    assert "9 faults, fine for paper with 4 forklifts" in capsys.readouterr().out
    assert main(["faults", "check", "mixed", "--vehicles", "2"]) == 2
    assert "the run has forklifts 1 to 2" in capsys.readouterr().err
