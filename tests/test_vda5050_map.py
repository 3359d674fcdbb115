"""`fleet vda5050 map`: a forklift layout's nodes and edges for a VDA 5050 master."""

from __future__ import annotations

import json
import math

import pytest

from fleet.cli import main
from fleet.vda5050.map import vda_map
from fleet.world.layout_file import load_layout


@pytest.mark.parametrize("name", ["small", "paper", "paper-cut", "paper-firewall"])
def test_every_node_is_a_pose_a_forklift_works_at_on_the_empty_floor(name):
    layout = load_layout(name)
    found = vda_map(layout)
    nodes = {n["nodeId"]: n for n in found["nodes"]}
    assert found["mapId"] == name and len(nodes) == len(found["nodes"])  # ids unique
    parks = [n for n in found["nodes"] if n["place"] == "park"]
    assert [n["pose"] for n in parks] == [str(p) for p in layout.vehicle_starts]
    docks = {n["of"]: n["pose"] for n in found["nodes"] if n["place"] == "station"}
    assert docks == {s.name: str(s.dock) for s in layout.stations}
    free = layout.grid_map()
    kind = layout.vehicle_kind
    stacks = {(s.cluster, s.index): s.cell for s in layout.stacks}
    for node in found["nodes"]:
        if node["place"] != "stack":
            continue
        cluster, index, side = node["nodeId"].removeprefix("stack-").rsplit("-", 2)
        pose = next(p for p in kind.handling_poses(stacks[cluster, int(index)])
                    if str(p) == node["pose"])
        assert "ENWS"[pose.heading] == side
        assert free.all_free(kind.body_cells_at_rest(pose))
    # every stack can be worked from some node
    assert {n["of"] for n in found["nodes"] if n["place"] == "stack"} == {
        f"{c}-{i}" for c, i in stacks}


def test_positions_are_metres_and_radians_in_the_layout_frame():
    layout = load_layout("small")
    for node in vda_map(layout)["nodes"]:
        col, row, heading = node["pose"].split(",")
        at = node["nodePosition"]
        assert at["mapId"] == "small"
        # the forklift's reference point at rest is its cell's centre
        assert (at["x"], at["y"]) == pytest.approx(layout.cell_center((int(col), int(row))))
        assert at["theta"] == pytest.approx(math.remainder(
            "ENWS".index(heading) * math.pi / 2, math.tau), abs=1e-6)


def test_edges_join_the_work_places_both_ways_and_name_known_nodes():
    found = vda_map(load_layout("small"))
    ids = {n["nodeId"] for n in found["nodes"]}
    ways = {(e["startNodeId"], e["endNodeId"]) for e in found["edges"]}
    assert len(ways) == len(found["edges"]) == len({e["edgeId"] for e in found["edges"]})
    assert all(a in ids and b in ids and (b, a) in ways for a, b in ways)
    assert ("station-1", "stack-a-1-S") in ways or any(
        a.startswith("station-") and b.startswith("stack-") for a, b in ways)
    assert not any(a.startswith("stack-") and b.startswith("stack-") for a, b in ways)


def test_the_command_writes_the_map_and_refuses_what_it_cannot(tmp_path, capsys):
    out = tmp_path / "small.json"
    assert main(["vda5050", "map", "small", "--out", str(out)]) == 0
    assert json.loads(out.read_text()) == vda_map(load_layout("small"))
    assert "70 nodes" in capsys.readouterr().out
    assert main(["vda5050", "map", "paper004"]) == 2
    err = capsys.readouterr().err
    assert "paper004 is a seed-004 floor" in err and "Traceback" not in err


def test_a_lane_layouts_nodes_are_its_slots_stations_and_piles_each_on_its_cell():
    """Seed 002: an AGV drives onto its places, each its own cell; edges join the stations
    and piles to every slot and the piles to the stations, both ways."""
    layout = load_layout("paper002")
    found = vda_map(layout)
    cells = {n["nodeId"]: (n["place"], n["pose"]) for n in found["nodes"]}
    assert cells == {**{f"station-{p.name}": ("packing", f"{p.cell[0]},{p.cell[1]},E")
                        for p in layout.packing},
                     **{f"slot-{s.name}": ("slot", f"{s.cell[0]},{s.cell[1]},E")
                        for s in layout.slots},
                     **{f"pile-{p.name}": ("pile", f"{p.cell[0]},{p.cell[1]},E")
                        for p in layout.piles}}
    for node in found["nodes"]:
        col, row, _ = node["pose"].split(",")
        assert (node["nodePosition"]["x"], node["nodePosition"]["y"]) == pytest.approx(
            layout.cell_center((int(col), int(row))))
    ways = {(e["startNodeId"], e["endNodeId"]) for e in found["edges"]}
    places = {kind: [i for i, (place, _) in cells.items() if place == kind]
              for kind in ("packing", "slot", "pile")}
    expected = {(a, b) for a in places["packing"] + places["pile"] for b in places["slot"]}
    expected |= {(a, b) for a in places["pile"] for b in places["packing"]}
    assert ways == expected | {(b, a) for a, b in expected}


@pytest.mark.parametrize(("name", "nodes", "vehicle_type"), [("small", 70, "forklift"),
                                                             ("paper002", 441, "agv")])
def test_the_map_as_a_lif_file_reads_back_with_every_node_edge_and_work_place(
        tmp_path, capsys, name, nodes, vehicle_type):
    """`--lif`: one LIF layout named after the layout, read back by the LIF library's own
    parser: the map's nodes at their positions and headings (pick and drop where forklifts
    work), its edges, a station for each station and each stack with its sides as
    interaction nodes."""
    from vdma_lif.parser import LIFParser

    out = tmp_path / f"{name}.lif.json"
    assert main(["vda5050", "map", name, "--lif", "--out", str(out)]) == 0
    assert f"LIF 1.0.0 layout {name}, {nodes} nodes" in capsys.readouterr().out
    (layout,) = LIFParser.from_file(str(out)).layouts
    found = vda_map(load_layout(name))
    assert layout.layout_id == name
    by_id = {n.node_id: n for n in layout.nodes}
    assert by_id.keys() == {n["nodeId"] for n in found["nodes"]}
    for n in found["nodes"]:
        lif = by_id[n["nodeId"]]
        (props,) = lif.vehicle_type_node_properties
        position = n["nodePosition"]
        assert (lif.node_position.x, lif.node_position.y, props.theta, lif.map_id) == (
            position["x"], position["y"], position["theta"], name)
        assert props.vehicle_type_id == vehicle_type
        # a forklift works stacks and stations, an AGV lifts shelves in their slots
        assert [a.action_type for a in props.actions or []] == (
            ["pick", "drop"] if n["place"] in ("stack", "station", "slot") else [])
    assert {(e.edge_id, e.start_node_id, e.end_node_id) for e in layout.edges} == {
        (e["edgeId"], e["startNodeId"], e["endNodeId"]) for e in found["edges"]}
    sides = {}
    for n in found["nodes"]:
        if n["place"] != "park":
            sides.setdefault(f"{n['place']}-{n['of']}", set()).add(n["nodeId"])
    assert {s.station_id: set(s.interaction_node_ids) for s in layout.stations} == sides


def _order(layout: str) -> dict:
    """A two-edge order on the layout's map: from the first park to a station to pick, then
    to a stack to drop."""
    nodes = {n["nodeId"]: n for n in vda_map(load_layout(layout))["nodes"]}
    station = next(i for i in nodes if i.startswith("station-"))
    stack = next(i for i in nodes if i.startswith("stack-"))
    visits = [("park-1", []), (station, [{"actionType": "pick", "actionId": "a1",
                                          "blockingType": "HARD"}]),
              (stack, [{"actionType": "drop", "actionId": "a2", "blockingType": "HARD"}])]
    return {
        "headerId": 1, "timestamp": "2026-12-05T08:00:00.000Z", "version": "2.0.0",
        "manufacturer": "fleet", "serialNumber": "forklift-1", "orderId": "o1",
        "orderUpdateId": 0,
        "nodes": [{"nodeId": i, "sequenceId": 2 * k, "released": True, "actions": actions,
                   "nodePosition": nodes[i]["nodePosition"]}
                  for k, (i, actions) in enumerate(visits)],
        "edges": [{"edgeId": f"e{k}", "sequenceId": 2 * k + 1, "released": True,
                   "startNodeId": visits[k][0], "endNodeId": visits[k + 1][0], "actions": []}
                  for k in range(2)]}


def test_check_puts_an_order_to_a_forklift_at_its_first_node(tmp_path, capsys):
    path = tmp_path / "order.json"
    path.write_text(json.dumps(_order("small")))
    assert main(["vda5050", "check", "order", str(path), "--layout", "small"]) == 0
    assert "accepts it: 2 edges released" in capsys.readouterr().out
    unknown = _order("small")
    unknown["nodes"][2]["nodeId"] = unknown["edges"][1]["endNodeId"] = "stack-nowhere"
    path.write_text(json.dumps(unknown))
    assert main(["vda5050", "check", "order", str(path), "--layout", "small"]) == 1
    assert "rejects it: noRouteError: node stack-nowhere" in capsys.readouterr().out


def test_check_names_what_is_wrong_with_a_message(tmp_path, capsys):
    path = tmp_path / "order.json"
    wrong = _order("small")
    wrong["orderUpdateId"] = "zero"
    path.write_text(json.dumps(wrong))
    assert main(["vda5050", "check", "order", str(path)]) == 1
    assert "at $.orderUpdateId: 'zero' is not of type 'integer'" in capsys.readouterr().out
    path.write_text("{nodes: ")
    assert main(["vda5050", "check", "order", str(path)]) == 2
    err = capsys.readouterr().err
    assert "not JSON" in err and "Traceback" not in err
