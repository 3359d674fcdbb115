"""The command line as a user meets it, run in-process through fleet.cli.main."""

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from fleet.cli import main
from fleet.world.layout_file import parse_layout

EXAMPLES = Path(__file__).parent.parent / "examples"


def test_layout_list_and_show(capsys):
    assert main(["layout", "list"]) == 0
    out = capsys.readouterr().out
    assert "paper" in out and "136 stacks" in out and "small" in out
    assert main(["layout", "show", "paper"]) == 0
    out = capsys.readouterr().out
    assert "111#3333PPn555555o" in out
    assert "stacks   136 in 6 clusters: s1 15, s2 15, s3 20, s4 20, s5 33, s6 33" in out


def test_layout_generate_then_check(tmp_path, capsys):
    out_file = tmp_path / "wide.toml"
    assert main(["layout", "generate", "--aisles", "1", "--depth", "4", "--lane-depth", "2",
                 "--vehicles", "2", "--out", str(out_file)]) == 0
    layout = parse_layout(out_file.read_text(), str(out_file))
    assert len(layout.stacks) == 32 and len(layout.vehicle_starts) == 2
    capsys.readouterr()
    assert main(["layout", "check", str(out_file)]) == 0
    assert "ok: 32 stacks" in capsys.readouterr().out


def test_layout_check_reports_every_problem(tmp_path, capsys):
    text = parse_source("small").replace('"0,7..0,5", "1,7..1,5", "2,7..2,5", "3,7..3,5"',
                                         '"0,5..3,5", "3,6..0,6", "0,7..3,7"')
    bad = tmp_path / "bad.toml"
    bad.write_text(text.split('drawing = """')[0] + text.split('"""', 2)[2])
    assert main(["layout", "check", str(bad)]) == 1
    err = capsys.readouterr().err
    assert "cluster a stack" in err and "problem(s)" in err


def test_layout_check_structural_error_exits_2(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text('name = "x"\n[bounds]\nx = [0, 10]\ny = [0, 9]\n')
    assert main(["layout", "check", str(bad)]) == 2
    assert "bounds: y span 9 m is not a whole number of 2 m cells" in capsys.readouterr().err


def test_plan_with_other_forklifts_and_png(tmp_path, capsys):
    png = tmp_path / "plan.png"
    code = main(["plan", "--from", "p1", "--to", "s1#1", "--reserved",
                 str(EXAMPLES / "three_forklifts.toml"), "--png", str(png)])
    out = capsys.readouterr().out
    assert code == 0, out
    assert "3 other vehicles planned" in out and "parked there to infinity" in out
    assert png.stat().st_size > 10_000 and png.read_bytes()[:4] == b"\x89PNG"


def test_plan_without_a_path_exits_1(tmp_path, capsys):
    assert main(["plan", "--layout", "small", "--from", "p1", "--to", "1,6,W"]) == 0
    capsys.readouterr()
    full = tmp_path / "full.toml"
    full.write_text("[filled]\na = 12\n")  # now the pose stands on filled stacks
    code = main(["plan", "--layout", "small", "--from", "p1", "--to", "1,6,W",
                 "--reserved", str(full)])
    assert code == 1
    assert "no trajectory: goal blocked" in capsys.readouterr().out


def test_plan_on_a_lane_layout_by_either_map_judged_by_the_lane_oracle(capsys):
    """Seed 002 on the command line: the lanes mode keeps the lane rules; the paper's literal
    map, direction-blind, drives slot s-3-3 to p1 west on the eastbound lane (the finding of
    docs/planning-002.md), which the oracle names and the exit status says."""
    assert main(["plan", "--layout", "paper002", "--from", "s-3-3", "--to", "p1"]) == 0
    out = capsys.readouterr().out
    assert out.splitlines()[1] == "3,3 3,4 3,5 2,5 1,4 1,3 1,2 1,1 1,0 0,0"
    assert "g = 9.40 s" in out and "lane rules: kept" in out
    code = main(["plan", "--layout", "paper002", "--from", "s-3-3", "--to", "p1",
                 "--map", "literal"])
    out = capsys.readouterr().out
    assert code == 1 and "(3, 4) -> (2, 4): wrong-way" in out
    assert main(["plan", "--layout", "micro-cross", "--from", "s-2-2", "--to", "s-7-7",
                 "--map", "literal"]) == 2
    assert "micro-cross is not paper002-shaped" in capsys.readouterr().err
    assert main(["plan", "--layout", "paper002", "--from", "s-99-2", "--to", "p1"]) == 2
    assert "has no slot, packing station or pile of that name" in capsys.readouterr().err


def test_bad_place_is_named(capsys):
    assert main(["plan", "--from", "p9", "--to", "s1#1"]) == 2
    assert "place 'p9' is not a pose 'col,row,H', a station (p1, p2, p3, p4)" in \
        capsys.readouterr().err


def test_bench_planner_json(capsys):
    assert main(["bench", "planner", "--queries", "5", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["queries"] == 5
    assert {"p50_ms", "p95_ms", "max_ms", "success_rate"} <= result.keys()
    assert 0.0 <= result["success_rate"] <= 1.0


def test_bench_planner004_compares_heap_and_list_on_the_same_queries(capsys):
    assert main(["bench", "planner004", "--queries", "4", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["queries"] == 16 and result["found"] == 16 and result["same_paths"] == 16
    assert result["heap_total_s"] > 0 and result["list_total_s"] > 0
    assert result["length_on"] == result["length_off"] and result["lengthened"] == 0
    assert result["turns_on"] <= result["turns_off"]


def test_bench_seed004_sets_heat_items_turns_and_fleet_sizes_side_by_side(tmp_path, capsys):
    assert main(["bench", "seed004", "--seeds", "1", "--orders", "24", "--vehicles", "6",
                 "--sizes", "3,6", "--heat-weights", "2,8", "--jobs", "1", "--json",
                 "--plots", str(tmp_path)]) == 0
    out = capsys.readouterr()
    result = json.loads(out.out)
    assert f"wrote {tmp_path / 'heat.png'}" in out.err
    assert (tmp_path / "heat.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    fields = {"completion_s", "head_on", "crossing", "replans", "path_length", "turns"}
    assert fields <= result["heat"]["off"].keys() and fields <= result["heat"]["on"].keys()
    for variant in ("off", "on"):  # the head-on conflicts' replans are some of the replans
        assert 0 <= result["heat"][variant]["replans_head_on"] <= \
            result["heat"][variant]["replans"]
    assert result["heat"]["off"] != result["heat"]["on"]  # the heat cost changed the routes
    assert set(result["items"]) == {"baseline", "recall", "turn", "heap"}
    # The heap finds the same paths as the list: only the time spent planning differs.
    same = {k: v for k, v in result["items"]["heap"].items() if k != "planning_s"}
    assert same == {k: v for k, v in result["items"]["baseline"].items() if k != "planning_s"}
    assert result["turn_example"]["length_off"] == result["turn_example"]["length_on"] == 26
    assert result["turn_example"]["turns_on"] < result["turn_example"]["turns_off"]
    assert set(result["fleet_sizes"]) == {"3", "6"}
    # the seed's weight is Table 5's "on"; another weight is a run of its own against off
    weights = result["heat_weights"]
    assert set(weights) == {"2", "8"}
    assert {k: weights["2"][k] for k in fields} == {k: result["heat"]["on"][k] for k in fields}
    assert weights["8"]["change"]["turns"] == pytest.approx(
        weights["8"]["turns"] / result["heat"]["off"]["turns"] - 1)
    assert result["clashes"] == result["bad_moves"] == result["rule_breaches"] == \
        result["yield_breaches"] == 0 and result["runs"] == 9
    assert all(isinstance(v, bool) for v in result["checks"].values())


def test_bench_runtime004_compares_processes_with_in_process_and_paces_real_time(capsys):
    assert main(["bench", "runtime004", "--orders", "3", "--vehicles", "2", "--repeats", "1",
                 "--agents", "3", "--rt-orders", "2", "--speed", "50", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    side = result["side_by_side"]
    assert side["same_record"] and side["passed"] and side["cells_driven"] > 0
    assert side["ratio"] > 0 and side["processes_ms_per_cell"] > 0
    (rt,) = result["real_time"]
    assert rt["vehicles"] == 3 and rt["instants"] > 0 and rt["rss_per_agent_mb"] > 10
    assert 0 <= rt["lateness_p50_s"] <= rt["lateness_p99_s"]
    assert rt["keeps_real_time"] == (rt["lateness_p99_s"] <= 0.1)  # fleet bench runtime's


def test_the_paired_sign_flip_test_is_exact():
    from bench.seed004 import lower_p

    assert lower_p([-3.0] * 10) == 1 / 1024  # only the observed signs are as low
    assert lower_p([2.0, -1.0]) == 0.75  # of the sums 1, 3, -3, -1, three are 1 or less
    assert lower_p([1.0] * 4) == 1.0 and lower_p([]) is None


def test_bench_seed004_refuses_a_fleet_paper004_cannot_park(capsys):
    assert main(["bench", "seed004", "--vehicles", "500"]) == 2
    assert "paper004 parks 96 AGVs, not 500" in capsys.readouterr().err


def parse_source(name: str) -> str:
    from importlib import resources

    return resources.files("fleet.world.layouts").joinpath(f"{name}.toml").read_text()


def test_run_then_plot(tmp_path, capsys):
    assert main(["run", "--layout", "small", "--strategy", "comprehensive",
                 "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "mission fill on small with 2 forklifts, strategy comprehensive" in out
    assert "stacks             24" in out
    assert "safety             pass: 0 overlaps, 0 moments outside a reservation" in out
    assert "work               pass: 24 of 24 stacks served, 0 twice, 0 lost" in out
    assert "messages           pass" in out and "0 lost, 0 malformed" in out
    wide = [line for line in out.splitlines() if len(line) > 80 and str(tmp_path) not in line]
    assert wide == []  # an 80-column terminal shows it as printed (a long path stays whole)
    end = float(re.search(r"end time +([\d.]+) s", out)[1])
    before = sorted(tmp_path.iterdir())
    assert main(["plot", str(tmp_path), "--at", "100", "--at", "1e6", "--no-gif"]) == 2
    assert capsys.readouterr().err == (f"fleet plot: error: --at 1000000: the run ended at "
                                       f"{end:.2f} s; snapshots are drawn from 0 to {end:.2f} s\n")
    assert sorted(tmp_path.iterdir()) == before  # refused before drawing anything
    assert main(["plot", str(tmp_path), "--at", "100", "--no-gif"]) == 0
    out = capsys.readouterr().out
    for name in ("filling.png", "gantt.png", "heatmap.png", "snapshot_00100.00.png"):
        assert (tmp_path / name).read_bytes()[:4] == b"\x89PNG", name
    assert "stacks per quarter of the end time" in out


def test_run_with_bad_weights_is_refused(tmp_path, capsys):
    bad = tmp_path / "w.json"
    bad.write_text("{not json")
    assert main(["run", "--layout", "small", "--weights", str(bad)]) == 2
    assert "not valid JSON" in capsys.readouterr().err


def test_train_writes_weights_the_run_can_use(tmp_path, capsys):
    weights = tmp_path / "small.json"
    assert main(["train", "--layout", "small", "--cycles", "1", "--lm-steps", "5",
                 "--out", str(weights)]) == 0
    out = capsys.readouterr().out
    assert "comprehensive" in out and "the networks of the last fit" in out
    assert (tmp_path / "small.training.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert main(["run", "--layout", "small", "--weights", str(weights),
                 "--out", str(tmp_path / "run")]) == 0  # not under the repository's runs/
    assert "strategy ann" in capsys.readouterr().out


def test_bench_strategies_json(capsys):
    assert main(["bench", "strategies", "--layout", "small", "--mission", "fill",
                 "--ann-seeds", "2", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert set(result["fill"]) == {"ann", "comprehensive", "greedy", "traffic", "balance"}
    bound = result["lower_bound_s"]["fill"]
    rows = [*result["fill"].values(), *result["ablation"]["fill"].values()]
    for row in rows:
        assert {"end_time_s", "failures", "wait_s", "wall_s"} <= row.keys()
        assert row["end_time_s"] >= bound > 0
        assert row["ratio_to_bound"] == pytest.approx(row["end_time_s"] / bound, abs=1e-3)
        parts = {k: v for k, v in row["gap"].items() if k != "faster_s"}  # not a part
        assert sum(parts.values()) == pytest.approx(2 * row["end_time_s"], abs=0.1)
    assert list(result["ablation"]["fill"]) == [
        "all terms", "without G_d", "without H", "without I_d", "without J_d,0 (H, I_d)"]
    assert 0 < result["relaxed_bound_s"]["fill"] < bound
    solo = result["solo"]["fill"]  # the first forklift alone never beats the pair
    assert solo["end_time_s"] >= result["fill"]["comprehensive"]["end_time_s"]
    assert solo["per_forklift_s"] == pytest.approx(solo["end_time_s"] / 2, abs=0.01)
    assert sum(solo["gap"].values()) - solo["gap"]["faster_s"] == pytest.approx(
        solo["end_time_s"], abs=0.1)
    seeds = result["ann_seeds"]
    assert seeds["training"] == {"cycles": 3, "seeds": [0, 1]}
    assert [r["seed"] for r in seeds["fill"]["runs"]] == [0, 1]
    ends = [r["end_time_s"] for r in seeds["fill"]["runs"]]
    assert min(ends) >= bound
    assert seeds["fill"]["end_time_s"]["mean"] == pytest.approx(sum(ends) / 2, abs=0.01)
    assert seeds["fill"]["mean_vs_comprehensive"] == pytest.approx(
        sum(ends) / 2 / result["fill"]["comprehensive"]["end_time_s"] - 1, abs=1e-4)


def test_bench_runtime_json(capsys):
    assert main(["bench", "runtime", "--commits", "20", "--ratio-layout", "small",
                 "--ratio-repeats", "1", "--agents", "2,3", "--window", "2", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["commits"] == 20 and result["refused"] == 0
    assert 0 < result["commit_p50_ms"] <= result["commit_p99_ms"] <= result["commit_max_ms"]
    assert result["same_record"] is True  # processes and in-process gave one record
    assert result["multiprocess_ratio"] == pytest.approx(
        result["multiprocess_wall_s"] / result["inprocess_wall_s"], abs=0.01)
    assert [row["agents"] for row in result["fleets"]] == [2, 3]
    assert result["max_realtime_agents"] in (0, 2, 3)
    assert all(row["rss_per_agent_mb"] > 10 for row in result["fleets"])


def test_bench_recorder_json(capsys):
    assert main(["bench", "recorder", "--rates", "500", "--seconds", "1", "--repeats", "0",
                 "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    [row] = result["rates"]
    assert row["rate"] == 500 and row["sent"] >= 475  # paced for one second
    assert row["lost"] == 0 and row["recorded"] == row["sent"] and row["file_complete"]
    assert result["max_lossless_rate"] == 500 and result["goal_rate"] == 10_000
    assert "wall_time" not in result  # --repeats 0 skips the fills


def test_bench_faults_json(capsys):
    assert main(["bench", "faults", "--scenarios", "vehicle_breakdown", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert set(result) == {"fault_free", "vehicle_breakdown", "machine"}
    row, base = result["vehicle_breakdown"], result["fault_free"]
    assert row["completed"] and row["verdicts_pass"] and base["verdicts_pass"]
    assert (row["overlaps"], row["outside_reservation"], row["stacks_lost"],
            row["stacks_duplicated"]) == (0, 0, 0, 0)
    # the breakdown was reported and seen, recovered from, and the repaired forklift is back
    assert row["detect_s"] > 0 and row["recover_s"] > 0 and row["rejoin_s"] >= 0
    assert row["extra_s"] == pytest.approx(row["end_time_s"] - base["end_time_s"])
    assert main(["bench", "faults", "--scenarios", "nope"]) == 2


def test_bench_faults_on_an_order_mission_json(capsys):
    """On a lane layout the bench runs an order mission with the layout's own scenarios,
    counting orders lost or done twice from the final record."""
    assert main(["bench", "faults", "--layout", "paper002", "--orders", "12", "--vehicles",
                 "4", "--scenarios", "vehicle_breakdown", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    row, base = result["vehicle_breakdown"], result["fault_free"]
    assert row["completed"] and row["verdicts_pass"] and base["verdicts_pass"]
    assert (row["overlaps"], row["outside_reservation"], row["stacks_lost"],
            row["stacks_duplicated"]) == (0, 0, 0, 0)
    assert row["detected"] == row["faults"] == 1 and row["detect_s"] > 0
    assert main(["bench", "faults", "--layout", "small"]) == 2


def test_bench_faults_on_a_seed004_floor_json(capsys):
    """On paper004 the bench runs an order mission with the floor's own scenarios: a killed
    recorder (its successor catches up on the events) leaves the fault-free record and
    every verdict; a scenario the floor does not take is refused by name."""
    assert main(["bench", "faults", "--layout", "paper004", "--orders", "10", "--vehicles",
                 "4", "--scenarios", "kill_recorder", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    row, base = result["kill_recorder"], result["fault_free"]
    assert row["completed"] and row["verdicts_pass"] and base["verdicts_pass"]
    assert row["injected"] == 1  # the kill (and the restart 2 s later)
    assert row["same_record"] and row["extra_s"] == 0
    assert (row["overlaps"], row["outside_reservation"], row["stacks_lost"],
            row["messages_lost"]) == (0, 0, 0, 0)
    assert main(["bench", "faults", "--layout", "paper004", "--scenarios", "slow_planner"]) == 2
    assert "'slow_planner' is not for paper004" in capsys.readouterr().err


def test_a_reader_that_leaves_early_gets_no_traceback():
    """`fleet faults list | head -1`: the reader is gone before the output comes; the
    command stops quietly, with the shell's status for a broken pipe."""
    read, write = os.pipe()
    os.close(read)  # nobody will read: every write fails with EPIPE
    proc = subprocess.run([sys.executable, "-m", "fleet", "faults", "list"], stdout=write,
                          stderr=subprocess.PIPE, text=True, timeout=60)
    os.close(write)
    assert proc.returncode == 141 and proc.stderr == "", proc.stderr
