"""Hostile input for every decoder and loader: random bytes, valid msgpack of the wrong shape,
valid messages and files with one value made absurd (NaN, infinity, huge or negative numbers,
very long strings, the wrong type), truncations and flipped bits. Each loader either returns
a valid object or raises its own documented error, naming what was wrong; nothing else ever
escapes. (tests/test_protocol.py, test_reservation_store.py and test_analysis.py hold the
round trips and the first hostile cases; this file extends them to every message type and
every file format.)"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
import re
import types
import typing
from pathlib import Path

import mcap.reader
import msgpack
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fleet.commands.layout import summary
from fleet.dispatching.decision import Strategy
from fleet.dispatching.mlp import ClusterMLPs
from fleet.dispatching.scorer import load_scorer
from fleet.dispatching.weights_file import WeightsError
from fleet.mission.engine import engine_options
from fleet.mission.seam import Task
from fleet.mission.spec import Mission, MissionKind
from fleet.planning.maneuvers import Manner
from fleet.planning.planner import HybridAStar
from fleet.planning.reservations import ReservationTable
from fleet.planning.rules004 import Direction
from fleet.planning.rules004 import Task as Task004
from fleet.planning.trajectory import FailureReason, PlanFailure, Pose, Trajectory
from fleet.recording.inprocess import recorded_run
from fleet.recording.reader import RecordingError, read_recording
from fleet.recording.writer import RecordingWriter
from fleet.runtime.tasks import result_from_wire, result_to_wire, task_from_wire, task_to_wire
from fleet.wire.protocol import (
    SCHEMA_VERSION,
    TYPES,
    CommitRequest,
    DirectionCode,
    ManeuverLabel,
    ManeuverOrRest,
    Message,
    PoseText,
    ProtocolError,
    Task004Name,
    TaskRequest,
    TaskResult,
    WireChange,
    body_of,
    build_message,
    decode,
    encode,
)
from fleet.world.layout import Layout, LayoutError
from fleet.world.layout_file import load_layout, parse_layout
from reservation.journal import Journal, JournalError
from reservation.store import ReservationStore

ROOT = Path(__file__).resolve().parent.parent
FUZZ = settings(max_examples=80, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.function_scoped_fixture,
                                       HealthCheck.too_slow])
FEW = settings(FUZZ, max_examples=40)
MESSAGE_TYPES = sorted(TYPES)  # every message type there is, as the protocol defines them

# -- values --------------------------------------------------------------------------------

INT64 = st.integers(-2**63, 2**64 - 1)  # what msgpack carries
SMALL_INT = st.integers(-3, 40)
LONG_TEXT = st.sampled_from(["x" * 100_000, "9" * 5000, "\u00e9\u4e2d\U0001f600" * 3000])
ABSURD_NUMBERS = st.sampled_from([math.nan, math.inf, -math.inf, -0.0, 1e308, -1e308,
                                  5e-324, 2**64 - 1, -2**63, -1, 0])
SCALARS = (st.none() | st.booleans() | SMALL_INT | INT64 | st.floats() | ABSURD_NUMBERS
           | st.text(max_size=12) | LONG_TEXT | st.binary(max_size=12))
HOSTILE = st.recursive(SCALARS, lambda inner: st.lists(inner, max_size=4)
                       | st.dictionaries(st.text(max_size=6), inner, max_size=3),
                       max_leaves=10)


WELL_FORMED_POSES = st.builds("{},{},{}".format, SMALL_INT | INT64, SMALL_INT | INT64,
                              st.sampled_from("ENWSenws"))
KNOWN_LABELS = st.sampled_from([m.label for m in Manner])
SYNTAX = {PoseText: WELL_FORMED_POSES, ManeuverLabel: KNOWN_LABELS,
          ManeuverOrRest: st.just("") | KNOWN_LABELS,
          Task004Name: st.sampled_from([t.value for t in Task004]),
          DirectionCode: st.sampled_from([int(d) for d in Direction])}


def valid(hint: typing.Any) -> st.SearchStrategy:
    """Values that `fleet.wire.protocol` accepts for a field of type `hint` (any that msgpack
    carries: infinities, the whole 64-bit range, any text where the field is free text)."""
    if hint in SYNTAX:
        return SYNTAX[hint]
    origin = typing.get_origin(hint)
    if origin in (types.UnionType, typing.Union):
        return st.one_of([valid(h) for h in typing.get_args(hint)])
    if hint is type(None):
        return st.none()
    if hint is bool:
        return st.booleans()
    if hint is int:
        return SMALL_INT | INT64
    if hint is float:
        return st.floats(allow_nan=False) | st.sampled_from([math.inf, -math.inf, 0.5])
    if hint is str:
        return st.text(max_size=12)
    if hint is dict:
        return st.dictionaries(st.text(max_size=6), SMALL_INT | st.text(max_size=4),
                               max_size=3)
    if origin is list:
        return st.lists(valid(typing.get_args(hint)[0]), max_size=4)
    if origin is tuple:
        return st.tuples(*(valid(h) for h in typing.get_args(hint)))
    raise AssertionError(f"no strategy for {hint!r}")  # a new kind of field: extend valid()


@functools.cache
def hints(cls: type[Message]) -> dict[str, typing.Any]:
    return typing.get_type_hints(cls, include_extras=True)


def required(f: dataclasses.Field) -> bool:
    return f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING


@functools.cache
def bodies(cls: type[Message]) -> st.SearchStrategy:
    """A valid body of `cls`, built from its dataclass fields: every required field, any of
    the optional ones."""
    fields = dataclasses.fields(cls)
    return st.fixed_dictionaries(
        {f.name: valid(hints(cls)[f.name]) for f in fields if required(f)},
        optional={f.name: valid(hints(cls)[f.name]) for f in fields if not required(f)})


def envelope(kind: str, body: object, **overrides) -> bytes:
    raw = {"v": SCHEMA_VERSION, "type": kind, "sender": "fuzz", "seq": 1, "t": 0.0,
           "body": body}
    raw.update(overrides)
    return msgpack.packb(raw, use_bin_type=True)


def no_nan(value: object) -> bool:
    if isinstance(value, float):
        return not math.isnan(value)
    if isinstance(value, list | tuple):
        return all(no_nan(v) for v in value)
    if isinstance(value, dict):
        return all(no_nan(v) for v in value.values())
    return True


def assert_valid(message: Message, cls: type[Message]) -> None:
    """What decode returned is a whole, valid message: of the type asked for, free of NaN in
    its typed fields, and it survives the wire unchanged."""
    assert type(message) is cls
    typed = {k: v for k, v in body_of(message).items() if hints(cls)[k] is not dict}
    assert no_nan(typed)
    assert decode(encode(message, "again", 1, 0.0)).message == message


# -- fleet.wire.protocol.decode -----------------------------------------------------------------

@FUZZ
@given(st.sampled_from(MESSAGE_TYPES).flatmap(lambda kind: st.tuples(
    st.just(kind), bodies(TYPES[kind]))))
def test_every_type_decodes_any_valid_body_exactly(case):
    kind, body = case
    message = decode(envelope(kind, body)).message
    assert_valid(message, TYPES[kind])
    got = body_of(message)
    assert msgpack.packb({k: got[k] for k in body}) == msgpack.packb(body)


@st.composite
def mutated_bodies(draw):
    """A valid body of some type with one thing wrong: a field of the wrong type or an absurd
    value, a field (or an item deep inside it) replaced, a field missing, a field unknown.
    Returns (type, body, the name the error must mention)."""
    kind = draw(st.sampled_from(MESSAGE_TYPES))
    cls = TYPES[kind]
    body = dict(draw(bodies(cls)))
    how = draw(st.sampled_from(["replace", "replace", "item", "drop", "unknown"]))
    name = draw(st.sampled_from([f.name for f in dataclasses.fields(cls)]))
    if how == "replace":
        body[name] = draw(HOSTILE)
    elif how == "item" and isinstance(body.get(name), list | tuple) and body[name]:
        items = list(body[name])
        k = draw(st.integers(0, len(items) - 1))
        if isinstance(items[k], list | tuple) and items[k] and draw(st.booleans()):
            inner = list(items[k])
            inner[draw(st.integers(0, len(inner) - 1))] = draw(HOSTILE)
            items[k] = inner
        else:
            items[k] = draw(HOSTILE)
        body[name] = items
    elif how == "drop":
        body.pop(name, None)
    else:
        name = draw(st.text(min_size=1, max_size=8).filter(lambda n: n not in hints(cls)))
        body[name] = draw(HOSTILE)
    return kind, body, name


@settings(FUZZ, max_examples=400)
@given(mutated_bodies())
def test_a_message_with_one_bad_field_is_refused_naming_it(case):
    kind, body, name = case
    try:
        message = decode(envelope(kind, body)).message
    except ProtocolError as exc:
        assert kind in str(exc) and repr(name)[1:-1] in str(exc), (str(exc), name)
    else:
        assert_valid(message, TYPES[kind])  # the change left it valid (an optional field...)


ENVELOPE_FIELDS = {"v": "schema version", "type": "message type", "sender": "sender",
                   "seq": "seq", "t": "t", "body": "body"}


@settings(FUZZ, max_examples=200)
@given(st.sampled_from(MESSAGE_TYPES).flatmap(lambda kind: st.tuples(
    st.just(kind), bodies(TYPES[kind]))), st.sampled_from(sorted(ENVELOPE_FIELDS)),
    st.none() | HOSTILE, st.none() | st.sampled_from(MESSAGE_TYPES))
def test_a_mangled_envelope_is_refused_naming_what_is_wrong(case, field, value, other):
    """One envelope field absurd or missing (None here: dropped), and maybe the body of one
    type under another type's name."""
    kind, body = case
    raw = {"v": SCHEMA_VERSION, "type": other or kind, "sender": "fuzz", "seq": 1, "t": 0.0,
           "body": body}
    if value is None:
        del raw[field]
    else:
        raw[field] = value
    try:
        envelope_ = decode(msgpack.packb(raw, use_bin_type=True))
    except ProtocolError as exc:
        text = str(exc)
        assert ENVELOPE_FIELDS[field] in text or (isinstance(raw.get("type"), str)
                                                  and raw["type"] in text), (text, field)
    else:
        assert_valid(envelope_.message, TYPES[raw["type"]])
        assert isinstance(envelope_.sender, str) and isinstance(envelope_.seq, int)
        assert not math.isnan(envelope_.sim_time)


@settings(FUZZ, max_examples=150)
@given(st.sampled_from(MESSAGE_TYPES).flatmap(lambda kind: bodies(TYPES[kind]).map(
    lambda body: envelope(kind, body))), st.data())
def test_a_truncated_or_padded_message_is_not_msgpack(payload, data):
    cut = data.draw(st.integers(0, len(payload) - 1), label="cut")
    with pytest.raises(ProtocolError, match="not msgpack"):
        decode(payload[:cut])
    extra = data.draw(st.binary(min_size=1, max_size=8), label="extra")
    with pytest.raises(ProtocolError, match="not msgpack"):
        decode(payload + extra)


REASONS = re.compile(r"not msgpack|envelope must be a map|schema version|unknown message type"
                     r"|sender|seq|\bt\b|body")


@settings(FUZZ, max_examples=150)
@given(HOSTILE | st.dictionaries(st.sampled_from(["v", "type", "sender", "seq", "t", "body"]),
                                 HOSTILE, max_size=6)
       | st.fixed_dictionaries({"v": st.just(1), "type": st.sampled_from(MESSAGE_TYPES)},
                               optional={"sender": HOSTILE, "seq": HOSTILE, "t": HOSTILE,
                                         "body": HOSTILE}))
def test_msgpack_of_the_wrong_shape_is_refused_with_a_reason(value):
    try:
        envelope_ = decode(msgpack.packb(value, use_bin_type=True))
    except ProtocolError as exc:
        assert REASONS.search(str(exc)), str(exc)
    else:
        assert_valid(envelope_.message, TYPES[value["type"]])


@pytest.mark.parametrize("payload, reason", [
    ("a string", "payload must be bytes"), (None, "payload must be bytes"),
    (12, "payload must be bytes"), (b"\x00" * (16 * 1024 * 1024 + 1), "exceeds"),
    (b"", "not msgpack"), (msgpack.packb(float("inf")), "envelope must be a map"),
    (msgpack.packb({1: 2}), "not msgpack"),  # map keys must be strings
    (envelope("vehicle.state", {b"vehicle": 1}), "unknown field b'vehicle'"),
    (envelope("dispatch.task", {"goals": [1]}), "missing field 'task_id'"),
], ids=lambda value: repr(value)[:24])
def test_odd_payloads_name_what_is_wrong(payload, reason):
    with pytest.raises(ProtocolError, match=re.escape(reason)):
        decode(payload)


# -- fleet.wire.convert ----------------------------------------------------------------------

POSES = (st.builds(lambda c, r, h: f"{c},{r},{h}", SMALL_INT, SMALL_INT,
                   st.sampled_from("ENWSenws"))
         | st.sampled_from(["", "1,2", "1,2,X", "a,b,N", "1,2,N,4", " 3 , 4 , s", "1.5,2,E",
                            "9" * 5000 + ",1,N", "1,-2,W", "\x00,\x00,N", ",,", "1,2,\u0131"])
         | st.text(max_size=10))


@FUZZ
@given(st.fixed_dictionaries({
    "task_id": st.text(max_size=8), "vehicle": SMALL_INT | INT64,
    "kind": st.sampled_from(["deliver", "return"]) | st.text(max_size=8),
    "start": POSES, "t_i": valid(float), "goals": st.lists(POSES, max_size=4),
    "filled": valid(list[tuple[int, int]]), "loaded": st.booleans(),
    "revision": SMALL_INT | INT64}))
def test_a_hostile_task_becomes_a_task_or_is_refused_naming_the_field(body):
    message = build_message(TaskRequest, body)  # what decode hands the agent
    try:
        task = task_from_wire(message)
    except ProtocolError as exc:
        assert re.match(r"dispatch\.task\.(kind|start|goals)", str(exc)), str(exc)
        return
    assert isinstance(task, Task) and task.goals
    assert all(isinstance(p, Pose) and 0 <= p.heading < 4 for p in (task.start, *task.goals))
    assert task_from_wire(task_to_wire(task, message.task_id, message.revision)) == task


@pytest.fixture(scope="module")
def planned() -> TaskResult:
    """A real committed trajectory on the wire (the small layout, one forklift)."""
    layout = load_layout("small")
    planner = HybridAStar(layout.grid_map(), layout.vehicle.dims)
    trajectory = planner.plan(1, layout.vehicle_starts[0], 0.0, [Pose((1, 4), 2)],
                              ReservationTable())
    assert isinstance(trajectory, Trajectory)
    return result_to_wire("d:1", 1, trajectory, 3, [])


LABELS = st.sampled_from([m.label for m in Manner]) | st.text(max_size=8)
STEP_PARTS = [LABELS, POSES, POSES, valid(float), valid(float), SMALL_INT | INT64,
              SMALL_INT | INT64, valid(list[tuple[int, int]])]


@st.composite
def hostile_result_bodies(draw, planned: TaskResult):
    """The planned result's body with one part replaced by a value of the right type but
    absurd: a field, a part of a step, a part of an interval; or a failure with any reason."""
    body = body_of(planned)
    where = draw(st.sampled_from(["field", "step", "interval", "failure"]))
    if where == "field":
        name = draw(st.sampled_from(["start", "goal", "t_start", "expansions", "vehicle"]))
        body[name] = draw(POSES if name in ("start", "goal") else
                          valid(hints(TaskResult)[name]))
    elif where == "step":
        steps = [list(s) for s in body["steps"]]
        k = draw(st.integers(0, len(steps) - 1))
        part = draw(st.integers(0, 7))
        steps[k][part] = draw(STEP_PARTS[part])
        body["steps"] = steps
    elif where == "interval":
        intervals = [list(iv) for iv in body["intervals"]]
        k = draw(st.integers(0, len(intervals) - 1))
        part = draw(st.integers(0, 3))
        intervals[k][part] = draw(SMALL_INT | INT64 if part < 2 else valid(float))
        body["intervals"] = intervals
    else:
        body.update(ok=False, failure=draw(st.sampled_from([r.value for r in FailureReason])
                                           | st.text(max_size=12)))
    return body


@FUZZ
@given(data=st.data())
def test_a_hostile_result_becomes_a_trajectory_or_is_refused_naming_the_field(planned, data):
    body = data.draw(hostile_result_bodies(planned))
    try:  # `decode` refuses a malformed pose or maneuver, the rest is refused on conversion
        message = build_message(TaskResult, body)
        result = result_from_wire(message)
    except ProtocolError as exc:
        assert re.match(r"dispatch\.task_result\.(failure|steps\[\d+\]|intervals|start|goal)",
                        str(exc)), str(exc)
        return
    assert isinstance(result, Trajectory | PlanFailure)
    if isinstance(result, Trajectory):
        assert all(iv.t0 < iv.t1 for iv in result.intervals)
        again = result_to_wire(message.task_id, message.vehicle, result, message.revision, [])
        assert result_from_wire(build_message(TaskResult, body_of(again))) == result
    else:
        assert result.reason.value == message.failure


# -- fleet.world.layout_file.parse_layout ----------------------------------------------------------

PAPER = (ROOT / "fleet" / "world" / "layouts" / "paper.toml").read_text()
PAPER_LINES = PAPER.split("\n")
ASSIGNMENTS = [k for k, line in enumerate(PAPER_LINES)
               if re.match(r"^\s*[a-z_]+\s*=\s*[^\s\"]|^\s*[a-z_]+\s*=\s*\"[^\"]", line)
               and '"""' not in line]
TOML_VALUES = (st.sampled_from(["nan", "inf", "-inf", "+inf", "1e400", "-1e400", "0", "-1",
                                "0.0", "-2.0", "1e-300", "9" * 4000, "-" + "9" * 4000,
                                "9" * 5000, "true", "[]", "{}", "[[]]", "[1, 2]", "[nan, inf]",
                                '"x"', '""', '"' + "x" * 20000 + '"', '"0,0..999999,999999"',
                                '["0,0..99999999999,99999999999"]', '"-1,-1"', '"1,1,Q"',
                                '"3,8..3,99999999999"', "[" * 5000, '"\\ud800"'])
               | SMALL_INT.map(str) | INT64.map(str) | st.floats().map(repr).filter(
                   lambda r: r not in ("nan", "inf", "-inf"))
               | st.text(max_size=20).map(json.dumps))


@st.composite
def damaged_layouts(draw) -> str:
    how = draw(st.sampled_from(["delete", "value", "number", "cut", "swap"]))
    lines = list(PAPER_LINES)
    if how == "delete":
        for k in sorted(draw(st.sets(st.integers(0, len(lines) - 1), min_size=1,
                                     max_size=4)), reverse=True):
            del lines[k]
    elif how == "value":
        k = draw(st.sampled_from(ASSIGNMENTS))
        key = lines[k].split("=")[0]
        lines[k] = f"{key}= {draw(TOML_VALUES)}"
    elif how == "number":  # one number anywhere (a cell, a pose, a bound) changed
        spots = [(k, m.span()) for k, line in enumerate(lines)
                 for m in re.finditer(r"-?\d+(\.\d+)?", line)]
        k, (a, b) = draw(st.sampled_from(spots))
        number = draw(SMALL_INT.map(str) | INT64.map(str)
                      | st.sampled_from(["99999999999", "-5", "1" + "0" * 30, "1e400"]))
        lines[k] = lines[k][:a] + number + lines[k][b:]
    elif how == "cut":
        text = "\n".join(lines)
        return text[:draw(st.integers(0, len(text) - 1))]
    else:  # two lines swapped
        a, b = draw(st.integers(0, len(lines) - 1)), draw(st.integers(0, len(lines) - 1))
        lines[a], lines[b] = lines[b], lines[a]
    return "\n".join(lines)


@settings(FUZZ, max_examples=300)
@given(damaged_layouts())
def test_a_damaged_layout_loads_or_is_refused_naming_the_problem(text):
    try:
        layout = parse_layout(text, "damaged.toml")
    except LayoutError as exc:
        assert str(exc).startswith("damaged.toml: ") and len(str(exc)) > 20, str(exc)
        return
    assert isinstance(layout, Layout)
    assert 0 < layout.cols * layout.rows <= 1_000_000 and math.isfinite(layout.cell_size)
    assert layout.render_drawing().count("\n") == layout.rows - 1
    assert all(0 <= s.cell[0] < layout.cols and 0 <= s.cell[1] < layout.rows
               for s in layout.stacks)
    assert all(math.isfinite(v) and v > 0 for v in dataclasses.astuple(layout.vehicle.dims))
    assert summary(layout)


def test_the_shipped_layout_itself_loads():
    assert len(parse_layout(PAPER, "paper").stacks) == 136  # the fuzzing above starts here


@pytest.mark.parametrize("old, new, reason", [
    ("cell_size = 2.0", "cell_size = nan", "layout: 'cell_size' must be a float"),
    ("cell_size = 2.0", "cell_size = 1" + "0" * 400, "layout: 'cell_size' must be a float"),
    ("cell_size = 2.0", "cell_size = " + "9" * 5000, "not valid TOML"),
    ("cell_size = 2.0", "cell_size = 1e-300", "more than a map may have"),
    ("x = [-18.0, 18.0]", "x = [-18.0, inf]", "bounds: x must be [min, max]"),
    ("x = [-18.0, 18.0]", "x = [-1" + "0" * 400 + ", 18]", "bounds: x must be [min, max]"),
    ("x = [-18.0, 18.0]", "x = [-1e308, 1e308]", "more than a map may have"),
    ("x = [-18.0, 18.0]", "x = [-18.0, 1e300]", "more than a map may have"),
    ('cells = ["3,8..3,11"]', 'cells = ["3,8..3,99999999999"]', "(3, 99999999999) is off the"),
    ('notches = ["3,7"]', 'notches = ["-9999999999,-9999999999..9999999999,9999999999"]',
     "is off the 18 x 12 map"),
    ('name = "s1"', 'name = ""', "cluster[0]: 'name' must not be empty"),
    ('kind = "forklift"', 'kind = "forklift"\nwidth = nan', "vehicle: 'width' must be a float"),
    ('kind = "forklift"', 'kind = "forklift"\nwheelbase = -inf', "'wheelbase' must be a float"),
    ('name = "paper"', 'name = "paper"\nx = ' + "[" * 5000, "nested too deep"),
], ids=lambda value: value[:30])
def test_absurd_layout_values_are_refused_naming_them(old, new, reason):
    """What fuzzing found, pinned: values that escaped as ValueError, OverflowError,
    IndexError or RecursionError, or ran out of memory listing a range of cells, and their
    neighbours."""
    assert PAPER.count(old) >= 1
    with pytest.raises(LayoutError, match=re.escape(reason)):
        parse_layout(PAPER.replace(old, new, 1), "t")


# -- the MLP weights -------------------------------------------------------------------------

WEIGHTS = {name: json.loads((ROOT / "fleet" / "dispatching" / "weights" / f"{name}.json")
                            .read_text()) for name in ("small", "paper")}
JSON_VALUES = (st.none() | st.booleans() | SMALL_INT | st.integers() | st.floats()
               | st.sampled_from([10**400, -10**400, 2**63, -1, 0, 12, 12.0, "12", "",
                                  "x" * 10_000, [], {}, [[]], [1e308] * 3])
               | st.text(max_size=8) | st.lists(st.floats(), max_size=3))


def json_paths(value, path=()):
    """Every place in a JSON document: (path of keys and indexes)."""
    yield path
    if isinstance(value, dict):
        for k, v in value.items():
            yield from json_paths(v, (*path, k))
    elif isinstance(value, list):
        for k, v in enumerate(value[:13]):  # the first rows of a matrix are enough
            yield from json_paths(v, (*path, k))


layouts = functools.cache(load_layout)
PATHS = {name: [p for p in json_paths(doc) if p] for name, doc in WEIGHTS.items()}


def replaced(doc, path, value, delete=False):
    doc = json.loads(json.dumps(doc))
    holder = doc
    for k in path[:-1]:
        holder = holder[k]
    if delete:
        del holder[path[-1]]
    else:
        holder[path[-1]] = value
    return doc


@st.composite
def damaged_weights(draw) -> tuple[str, str]:
    name = draw(st.sampled_from(sorted(WEIGHTS)))
    how = draw(st.sampled_from(["value", "value", "delete", "cut", "text"]))
    doc = WEIGHTS[name]
    if how in ("value", "delete"):
        path = draw(st.sampled_from(PATHS[name]))
        doc = replaced(doc, path, draw(JSON_VALUES), delete=how == "delete")
        return name, json.dumps(doc)
    text = json.dumps(doc)
    if how == "cut":
        return name, text[:draw(st.integers(0, len(text) - 1))]
    spots = [m.span() for m in re.finditer(r"-?\d+\.?\d*(e-?\d+)?", text)]
    a, b = draw(st.sampled_from(spots))
    number = draw(st.sampled_from(["9" * 5000, "1e400", "-1e400", "NaN", "Infinity", "[" * 5000,
                                   '"x"', "null", "1" + "0" * 400]))
    return name, text[:a] + number + text[b:]


@settings(FUZZ, max_examples=150)
@given(damaged_weights())
def test_damaged_weights_load_or_are_refused_naming_the_problem(tmp_path, case):
    name, text = case
    path = tmp_path / "weights.json"
    path.write_text(text)
    layout = layouts(name)
    try:
        mlps = ClusterMLPs.load(path)
    except WeightsError as exc:
        assert str(exc).startswith(f"{path}: ") and len(str(exc)) > len(str(path)) + 10
        return
    assert isinstance(mlps, ClusterMLPs) and mlps.clusters and isinstance(mlps.layout, str)
    assert math.isfinite(mlps.input_scale) and mlps.input_scale > 0 and mlps.trained_on >= 0
    scores = mlps([1.0] * len(mlps.clusters))
    assert len(scores) == len(mlps.clusters) and all(isinstance(s, float) for s in scores)
    try:
        assert load_scorer(layout, path).clusters == tuple(c.name for c in layout.clusters)
    except WeightsError as exc:
        assert "trained for clusters" in str(exc)


@pytest.mark.parametrize("path, value, reason", [
    (("target_mean", 0), 10**400, "'target_mean' must be 2 finite numbers"),
    (("input_scale",), 10**400, "'input_scale' must be a positive number"),
    (("input_scale",), math.inf, "'input_scale' must be a positive number"),
    (("nets", 0, "0.bias", 0), 10**400, "network 0 (a)"),
    (("nets", 1, "2.weight", 0, 3), None, "network 1 (b)"),
    (("nets", 0, "0.weight", 2, 1), "1.5", "network 0 (a): 0.weight must be finite numbers"),
    (("trained_on",), "many", "'trained_on' must be a whole number"),
    (("trained_on",), math.inf, "'trained_on' must be a whole number"),
    (("layout",), ["small"], "'layout' must be a layout name"),
], ids=lambda value: str(value)[:30])
def test_absurd_weight_values_are_refused_naming_them(tmp_path, path, value, reason):
    """What fuzzing found, pinned: numbers too large for a float and counts that are no
    numbers escaped as OverflowError, ValueError or TypeError."""
    file = tmp_path / "w.json"
    file.write_text(json.dumps(replaced(WEIGHTS["small"], path, value)))
    with pytest.raises(WeightsError, match=re.escape(reason)):
        ClusterMLPs.load(file)


@pytest.mark.parametrize("text", ["", "not json", "[" * 100_000, "1" * 5000, "NaN", "{}",
                                  '{"format": "fleet-mlp/1"}', "\udcff"],
                         ids=lambda text: repr(text)[:24])
def test_weights_that_are_no_weights_name_the_file(tmp_path, text):
    path = tmp_path / "w.json"
    path.write_bytes(text.encode(errors="surrogateescape"))
    with pytest.raises(WeightsError, match=re.escape(str(path))):
        ClusterMLPs.load(path)


# -- reservation.journal ---------------------------------------------------------------------

CHANGES = st.lists(st.builds(
    lambda op, vehicle, cells, t0, dt, release, rid: (op, vehicle, cells, t0, dt, release, rid),
    st.sampled_from(["commit", "release"]), st.integers(1, 4),
    st.lists(st.tuples(st.integers(0, 30), st.integers(0, 30)), max_size=5),
    st.floats(0, 1e4), st.floats(0.25, 100) | st.just(math.inf),
    st.none() | st.floats(0, 1e4), st.text(max_size=6)), min_size=1, max_size=8)


def journal_of(tmp_path: Path, ops) -> tuple[Path, list[WireChange], list[int]]:
    """A journal written by Journal.append, its changes and where each record ends."""
    path = tmp_path / "journal.msgpack"
    path.unlink(missing_ok=True)
    journal = Journal(path)
    changes, ends = [], []
    for revision, (op, vehicle, cells, t0, dt, release, rid) in enumerate(ops, start=1):
        intervals = [(c, r, t0, t0 + dt) for c, r in cells] if op == "commit" else []
        change = WireChange(revision, op, vehicle, intervals,
                        release if op == "commit" else (release or 0.0), rid)
        journal.append(change)
        changes.append(build_message(WireChange, body_of(change)))  # as replay builds it
        ends.append(path.stat().st_size)
    journal.close()
    return path, changes, ends


@FUZZ
@given(CHANGES, st.data())
def test_a_journal_cut_anywhere_keeps_exactly_its_complete_records(tmp_path, ops, data):
    path, changes, ends = journal_of(tmp_path, ops)
    whole = path.read_bytes()
    cut = data.draw(st.integers(0, len(whole)), label="cut")
    path.write_bytes(whole[:cut])
    complete = sum(end <= cut for end in ends)
    good = ends[complete - 1] if complete else 0
    replayed = Journal(path).replay()
    assert replayed.changes == changes[:complete]  # every complete record, nothing more
    assert replayed.torn_bytes == cut - good
    assert path.read_bytes() == whole[:good]  # the torn tail is cut off the file
    assert Journal(path).replay() == type(replayed)(changes[:complete], 0)


@FUZZ
@given(CHANGES.filter(lambda ops: len(ops) >= 2), st.data())
def test_garbage_in_the_middle_of_a_journal_names_the_record(tmp_path, ops, data):
    """Random bytes inserted after record k (of at least k + 1): replay refuses the journal
    naming record k + 1 and its byte, or (when the garbage happens to be a whole valid record
    itself) replays without losing a single real record. It never cuts off whole records as
    if they were a torn tail."""
    path, changes, ends = journal_of(tmp_path, ops)
    whole = path.read_bytes()
    k = data.draw(st.integers(0, len(ends) - 2), label="after record")
    garbage = data.draw(st.binary(min_size=1, max_size=12)
                        | st.sampled_from([b"\xc1", b"\xdb\xff\xff\xff\xff",
                                           b"\xdf\x00\x00\x00\x09", b"\x91", b"\x80",
                                           b"\xc6\x7f\xff\xff\xff", b"\xa8revision"]),
                        label="garbage")
    at = ends[k]
    path.write_bytes(whole[:at] + garbage + whole[at:])
    try:
        replayed = Journal(path).replay()
    except JournalError as exc:
        assert f"record {k + 2} at byte {at}" in str(exc), str(exc)
        assert path.read_bytes() == whole[:at] + garbage + whole[at:]  # nothing cut
        return
    real = [c for c in replayed.changes if c in changes]
    assert real == changes  # the garbage was a record of its own; every real one is there


def test_a_length_that_swallows_later_records_is_damage_not_a_torn_tail(tmp_path):
    """What fuzzing found: a string header claiming 4 GiB in the middle made every record
    after it look like one torn tail, and replay cut them all off the file."""
    ops = [("commit", 1, [(k, 0)], 0.0, 5.0, None, f"r{k}") for k in range(4)]
    path, _, ends = journal_of(tmp_path, ops)
    whole = path.read_bytes()
    path.write_bytes(whole[:ends[1]] + b"\xdb\xff\xff\xff\xff" + whole[ends[1]:])
    with pytest.raises(JournalError, match=f"record 3 at byte {ends[1]} is not a complete "
                                           f"record, yet a complete record follows"):
        Journal(path).replay()
    assert len(path.read_bytes()) == len(whole) + 5  # nothing cut off


# -- the reservation store -------------------------------------------------------------------

def hostile_commits() -> st.SearchStrategy:
    cell = SMALL_INT | INT64
    time = st.floats(allow_nan=False) | st.sampled_from([math.inf, -math.inf, 0.0, 5.0])
    return st.fixed_dictionaries({
        "request_id": st.sampled_from(["seed:1", "seed:2", ""]) | st.text(max_size=8)
        | LONG_TEXT,
        "vehicle": st.sampled_from([1, 2, 3, 0, -1]) | INT64,
        "intervals": st.lists(st.tuples(cell, cell, time, time), max_size=6)
        | st.lists(st.tuples(st.integers(0, 3), st.integers(0, 3), time, time), max_size=6),
    }, optional={"release_from": st.none() | time})


def seeded_store(path: Path | None = None) -> ReservationStore:
    store = ReservationStore(path)
    for k, (vehicle, cells) in enumerate([(1, [(0, 0), (0, 1)]), (2, [(1, 1), (2, 1)])]):
        store.handle(CommitRequest(f"seed:{k + 1}", vehicle,
                                   [(c, r, 0.0, math.inf) for c, r in cells]))
    return store


def table_state(store: ReservationStore):
    return store.revision, store.table.reservations(), [body_of(c) for c in store.log]


@settings(FUZZ, max_examples=200)
@given(st.lists(hostile_commits(), min_size=1, max_size=4))
def test_hostile_commits_never_raise_and_a_refusal_changes_nothing(tmp_path, commits):
    (tmp_path / "journal").unlink(missing_ok=True)  # each example starts a new journal
    store = seeded_store(tmp_path / "journal")
    try:
        for body in commits:
            request = decode(envelope(CommitRequest.TYPE, body)).message  # as it arrives
            before = table_state(store)
            known = request.request_id in store.replies
            outcome = store.handle(request)
            reply = outcome.reply
            assert reply.request_id == request.request_id
            if not reply.ok or known:  # a refusal, or a retry answered as before
                assert table_state(store) == before and outcome.published == []
                continue
            assert store.revision == before[0] + 1 == reply.revision
            assert [c.revision for c in outcome.published] == [reply.revision]
            for c, r, t0, t1 in request.intervals:  # the vehicle now holds what it asked
                assert store.table.conflict(request.vehicle + 1, (c, r), t0, t1) == \
                    request.vehicle
    finally:
        store.close()
    again = ReservationStore(tmp_path / "journal")  # and the journal says the same
    assert table_state(again)[:2] == table_state(store)[:2]
    again.close()


@settings(FUZZ, max_examples=150)
@given(st.sampled_from(MESSAGE_TYPES).flatmap(lambda kind: bodies(TYPES[kind]).map(
    lambda body: build_message(TYPES[kind], body))))
def test_any_message_handed_to_the_store_is_answered_and_a_refusal_changes_nothing(message):
    store = seeded_store()
    before = table_state(store)
    outcome = store.handle(message)
    assert isinstance(outcome.reply, Message)
    if getattr(outcome.reply, "ok", True) is False:
        assert table_state(store) == before and outcome.published == []


# -- fleet.recording.reader.read_recording ---------------------------------------------------

@pytest.fixture(scope="module")
def recording_bytes(tmp_path_factory) -> tuple[bytes, list, int]:
    """A small valid recording in small chunks (so a cut leaves several whole ones): the
    first few hundred messages of a fault-free fill of the small layout, and what it holds."""
    mission = Mission("small", MissionKind.FILL, Strategy.GREEDY)
    layout = load_layout("small")
    _, stream = recorded_run(mission, layout, engine_options(mission, layout, None))
    path = tmp_path_factory.mktemp("rec") / "run.mcap"
    writer = RecordingWriter(path, chunk_bytes=2048)
    writer.describe(stream[0].message)
    for seq, o in enumerate([*stream[:300], stream[-1]], start=1):
        writer.write(o.key, encode(o.message, o.sender, seq, o.sim_time), seq, o.sim_time)
    writer.close()
    whole = read_recording(path)
    assert whole.complete and whole.problem == "" and len(whole.messages) == 301
    with open(path, "rb") as f:
        chunks = mcap.reader.make_reader(f).get_summary().chunk_indexes
    assert len(chunks) > 10
    first_chunk_end = min(c.chunk_start_offset + c.chunk_length for c in chunks)
    return path.read_bytes(), whole.messages, first_chunk_end


@FUZZ
@given(data=st.data())
def test_a_cut_recording_keeps_exactly_what_was_complete(recording_bytes, tmp_path, data):
    whole, messages, first_chunk_end = recording_bytes
    cut = data.draw(st.integers(0, len(whole) - 1) | st.integers(0, first_chunk_end + 8),
                    label="cut")
    path = tmp_path / "cut.mcap"
    path.write_bytes(whole[:cut])
    try:
        recording = read_recording(path)
    except RecordingError as exc:
        assert str(path) in str(exc) and "MCAP" in str(exc)
        assert cut < first_chunk_end  # only a file cut before its first chunk is refused
        return
    assert not recording.complete and recording.problem
    assert recording.messages == messages[:len(recording.messages)]  # a prefix, nothing new
    if cut > len(whole) // 2:
        assert len(recording.messages) > 0


@FUZZ
@given(data=st.data())
def test_a_damaged_recording_keeps_every_chunk_before_the_damage(recording_bytes, tmp_path,
                                                                 data):
    """Bits flipped from byte p on: whatever a cut at p recovers, the damaged file gives too,
    in the same order; after that, only valid messages or payloads marked malformed."""
    whole, _, _ = recording_bytes
    at = data.draw(st.integers(0, len(whole) - 1), label="first flip")
    damaged = bytearray(whole)
    for k in sorted({at} | set(data.draw(st.lists(st.integers(at, len(whole) - 1),
                                                  max_size=3), label="more flips"))):
        damaged[k] ^= data.draw(st.integers(1, 255), label="xor")
    cut_path, path = tmp_path / "cut.mcap", tmp_path / "damaged.mcap"
    cut_path.write_bytes(whole[:at])
    path.write_bytes(bytes(damaged))
    try:
        before = read_recording(cut_path).messages
    except RecordingError:
        before = []
    try:
        recording = read_recording(path)
    except RecordingError as exc:
        assert str(path) in str(exc)
        assert before == []
        return
    assert recording.complete or recording.problem
    assert recording.messages[:len(before)] == before
    for r in recording.messages:
        assert (r.envelope is None) != (r.error == "")
    try:
        recording.layout()
    except (RecordingError, LayoutError) as exc:
        assert str(path) in str(exc)
