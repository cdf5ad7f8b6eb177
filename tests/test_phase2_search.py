"""Phase 2's instance search against every instance of small cells: each instance of the partial
plan is run (phase2.evaluate, every step given up, so only the geometry can stop it), and the
nogoods its infeasible runs give (phase2/nogood.py) are checked with a matcher written here from
their definition, not from the search's code:

- every infeasible run gives a nogood, and its own instance meets it;
- no instance that can be executed meets any nogood (a nogood never rules out an instance that
  would pass);
- prolog/partial_plan.pl's search, told every nogood, gives exactly the instances none rules
  out, each once (so it skips no executable instance, and the first it gives is one of them).

The cells: put-downs and a regrasp (turn_over, enclosed_part, putdown_blocked, riser_putdown,
whose nogoods fix a prefix) and a product whose parts in place block grasps (the stool, whose
nogoods name a few parts' moves).
"""
from __future__ import annotations

import functools
from pathlib import Path
from typing import Any

import pytest

from spar_py.phase2 import instance as phase2
from spar_py.planning.planner import Planner
from spar_py.planning import run as planning_run
from spar_py.planning.run import PlanRun

from paths import ROOT

#: Every instance of a cell's partial plan (partial_instances/2, in its order) as data, and the
#: network variables of each action (in its term and its operational preconditions).
_INSTANCES = """atom_string(_A, Pb), kb:with_problem(_A, (
  phase1(_A, [], plan(_P)), _P = partial(_Actions, _, _, _),
  findall([_Id, _Vs], ( member(action(_Id, _T, preconditions(_Ops, _), _, _), _Actions),
                        findall(_V, ( sub_term(_V, _T-_Ops), atom(_V) ), _Vs0), sort(_Vs0, _Vs) ), Vars),
  findall(_{steps: _Ds, bindings: _B, sources: _From},
          ( partial_instances(_P, _I), uncertainty:instance_steps(_I, _Steps, _Bs),
            maplist(uncertainty:step_dict, _Steps, _Ds), uncertainty:instance_sources(_I, _Src),
            uncertainty:sources_dict(_Src, _From), findall([_V1, _L1], member(_V1 = _L1, _Bs), _B) ), Is)))"""

#: The instances the search gives, told the nogoods ``Ngs`` ([Ids, Bindings, Step, Labels, Prefix,
#: Before] each: the instance it came from and its ids), each marked examined before the next.
_SEARCHED = """atom_string(_A, Pb), kb:with_problem(_A, (
  phase1(_A, [], plan(_P)),
  findall(_Ng, ( member([_Ids0, _Bs0, _St0, _Ls0, _Pf0, _Bf0], Ngs),
                 maplist(atom_string, _Ids, _Ids0), maplist([[_X, _Y], _X1 = _Y1]>>(atom_string(_X1, _X),
                 atom_string(_Y1, _Y)), _Bs0, _Bs), msort(_Bs, _BsS),
                 once(( partial_instances(_P, _I), _I = instance(_Steps, _BsI),
                        maplist(arg(1), _Steps, _Ids), msort(_BsI, _BsS) )),
                 atom_string(_St, _St0), maplist(atom_string, _Ls, _Ls0), maplist(atom_string, _Pf, _Pf0),
                 maplist([[_U, _W], _U1-_W1]>>(atom_string(_U1, _U), atom_string(_W1, _W)), _Bf0, _Bf),
                 partial_plan:instance_nogood(_P, _I, learnt(_St, _Ls, _Pf, _Bf), _Ng) ), _Ngs),
  partial_plan:instance_search(_S0), foldl(partial_plan:search_nogood, _Ngs, _S0, _S1),
  _State = state(_S1, []),
  (   repeat,
      arg(1, _State, _S),
      (   partial_plan:next_instance(_P, _S, _In)
      ->  partial_plan:search_examined(_In, _S, _S2), nb_setarg(1, _State, _S2),
          _In = instance(_St2, _Bd2), maplist(arg(1), _St2, _Ids2),
          findall([_V2, _L2], member(_V2 = _L2, _Bd2), _Key2),
          arg(2, _State, _Acc), nb_setarg(2, _State, [[_Ids2, _Key2]|_Acc]),
          fail
      ;   !
      )
  ),
  arg(2, _State, Got)))"""

CELLS = ["turn_over", "enclosed_part", "putdown_blocked", "riser_putdown", "fabrica_stool_circular", "wide_pins"]

#: Two headed pins into plate_pins' plate whose heads (radius 26 mm, the bores 60 mm apart) leave
#: 8 mm between them: a hand closing on one across that gap meets the other if it is in place,
#: so some grasps of a pin fail in one order of the two insertions and not in the other.
_WIDE_PIN = """object: wide_pin
units: {length: mm, angle: deg}
shape:
  - {cylinder: {radius: 26, z: [0, 12]}}
  - {cylinder: {radius: 5, z: [12, 20]}}
features:
  - {kind: peg, name: shaft, radius: 5, axis: {origin: [0, 0, 12], direction: [0, 0, 1]}, length: 8}
"""
_WIDE_PINS = """product: wide_pins
units: {length: mm, angle: deg}
parts:
  plate: {model: OBJ/plate2.yaml}
  pin_a: {model: HERE/wide_pin.yaml, pose: {xyz: [-30, 0, 26], rpy: [180, 0, 0]}}
  pin_b: {model: HERE/wide_pin.yaml, pose: {xyz: [30, 0, 26], rpy: [180, 0, 0]}}
mates:
  - {peg: pin_a.shaft, hole: plate.bore_a}
  - {peg: pin_b.shaft, hole: plate.bore_b}
"""


def _problem(name: str, where: Path) -> Path:
    """The problem file of cell ``name``: kb/problems' own, or wide_pins (plate_pins' cell with the
    wide pins) written under ``where``."""
    if name != "wide_pins":
        return ROOT / "kb" / "problems" / f"{name}.yaml"
    (where / "wide_pin.yaml").write_text(_WIDE_PIN)
    (where / "product.yaml").write_text(_WIDE_PINS.replace("OBJ", str(ROOT / "kb" / "objects"))
                                        .replace("HERE", str(where)))
    text = (ROOT / "kb" / "problems" / "plate_pins.yaml").read_text()
    text = (text.replace("problem: plate_pins", "problem: wide_pins")
            .replace("../products/plate_pins.yaml", str(where / "product.yaml"))
            .replace("../robots/", str(ROOT / "kb" / "robots") + "/")
            .replace("assembled(plate_pins)", "assembled(wide_pins)"))
    (where / "problem.yaml").write_text(text)
    return where / "problem.yaml"


def _key(ids: list[str], bindings: list[list[str]]) -> tuple:
    return tuple(ids), tuple(sorted(tuple(b) for b in bindings))


def _matches(ng: dict[str, Any], labels: dict[str, str], inst: dict[str, Any]) -> bool:
    """Whether instance ``inst`` meets nogood ``ng`` (its variables bound to ``labels``): the same
    labels, its order starting with ``prefix`` and putting each ``a`` before its ``b``."""
    ids = [s["id"] for s in inst["steps"]]
    pos = {i: k for k, i in enumerate(ids)}
    bound = dict(map(tuple, inst["bindings"]))
    return (all(bound.get(v) == lab for v, lab in labels.items())
            and ids[:len(ng["prefix"])] == ng["prefix"]
            and all(pos[a] < pos[b] for a, b in ng["before"]))


@pytest.fixture(scope="module", params=CELLS)
def exhaustive(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """A cell's every instance with its run's status and nogood (:func:`_exhaust`)."""
    return _exhaust(str(_problem(request.param, tmp_path_factory.mktemp(request.param))))


@functools.cache
def _planner() -> Planner:
    """One planner for the module: its cells' kept answers serve the exhaustive runs and the plan."""
    return Planner()


@functools.cache
def _exhaust(path: str) -> dict[str, Any]:
    """Every instance of the cell of problem file ``path`` with its run's status and nogood, and each
    nogood's labels (the bindings, in the instance it came from, of the variables of its step and of
    its ``labels``)."""
    planner = _planner()
    cell = planner.load_problem(path)
    run = PlanRun(planner.cache_of(cell), planner.run_options(cell))
    with planner.engine.session(run):
        ans = planner.engine.query_once(_INSTANCES, {"Pb": cell.name})
    vars_of = {i: set(vs) for i, vs in ans["Vars"]}
    out = []
    for inst in ans["Is"]:
        steps = inst["steps"]
        ev = phase2.evaluate(run.world.cache, steps, inst["sources"], [s["id"] for s in steps],
                             motion=run.world.options.motion)
        labels = None
        if ev.nogood is not None:
            bound = dict(map(tuple, inst["bindings"]))
            names = set().union(*(vars_of[i] for i in [ev.nogood["step"], *ev.nogood["labels"]]))
            labels = {v: bound[v] for v in names if v in bound}
        out.append({**inst, "status": ev.status, "at": ev.at, "nogood": ev.nogood, "labels": labels})
    return {"planner": planner, "cell": cell, "instances": out}


def test_every_infeasible_run_gives_a_nogood_its_instance_meets(exhaustive) -> None:
    insts = exhaustive["instances"]
    bad = [i for i in insts if i["status"] == "infeasible"]
    assert bad, "the cell has no infeasible instance: nothing is checked"
    for inst in bad:
        assert inst["nogood"] is not None, (inst["at"], [s["id"] for s in inst["steps"]])
        assert inst["nogood"]["step"] == inst["at"]
        assert _matches(inst["nogood"], inst["labels"], inst)


def test_no_nogood_rules_out_an_executable_instance(exhaustive) -> None:
    insts = exhaustive["instances"]
    ngs = [(i["nogood"], i["labels"]) for i in insts if i["nogood"] is not None]
    ok = [i for i in insts if i["status"] == "ok"]
    for inst in ok:
        hit = next((ng for ng, labels in ngs if _matches(ng, labels, inst)), None)
        assert hit is None, (hit, [s["id"] for s in inst["steps"]], inst["bindings"])
    if exhaustive["cell"].name in ("fabrica_stool_circular", "wide_pins"):  # a nogood rules out instances unrun
        assert max(sum(_matches(ng, labels, i) for i in insts) for ng, labels in ngs) >= 2


def test_the_search_gives_exactly_the_instances_no_nogood_rules_out(exhaustive) -> None:
    insts = exhaustive["instances"]
    planner, cell = exhaustive["planner"], exhaustive["cell"]
    ngs = [[[s["id"] for s in i["steps"]], i["bindings"], i["nogood"]["step"], i["nogood"]["labels"],
            i["nogood"]["prefix"], i["nogood"]["before"]] for i in insts if i["nogood"] is not None]
    run = PlanRun(planner.cache_of(cell), planner.run_options(cell))
    with planner.engine.session(run):
        got = planner.engine.query_once(_SEARCHED, {"Pb": cell.name, "Ngs": ngs})["Got"]
    given = [_key(ids, b) for ids, b in got]
    assert len(given) == len(set(given)), "an instance given twice"
    pairs = [(i["nogood"], i["labels"]) for i in insts if i["nogood"] is not None]
    free = {_key([s["id"] for s in i["steps"]], i["bindings"]) for i in insts
            if not any(_matches(ng, labels, i) for ng, labels in pairs)}
    assert set(given) == free
    ok = {_key([s["id"] for s in i["steps"]], i["bindings"]) for i in insts if i["status"] == "ok"}
    assert ok <= set(given)


def _grasp(steps: list[dict[str, Any]], part: str) -> str | None:
    """The grasp the (last) pickup of ``part`` in ``steps`` binds."""
    picks = [s for s in steps if s["name"] == "pickup" and s["args"][0] == part]
    return str(picks[-1]["args"][1]) if picks else None


def test_a_grasp_that_fails_by_itself_is_changed_in_the_second_instance(monkeypatch) -> None:
    """The stool planned: its first instance stops at a foot's insertion. Every instance of the cell
    that holds that foot by the same grasp stops there too or earlier (the legs that block it are in place
    before the feet in every order: the failure depends on that grasp alone), and some holding it
    by another can be executed; the second instance phase 2 examines takes another grasp of it
    (the enumeration's own next instance would keep it and change a later choice)."""
    seen: list[tuple[tuple, list[dict[str, Any]], dict[str, Any]]] = []
    orig = planning_run.PlanRun.evaluate

    def evaluate(self, steps, sources=None, given_up=(), sensing=None):
        out = orig(self, steps, sources, given_up, sensing)
        manip = tuple((s["id"], str(s["args"])) for s in steps if s["name"] in ("pickup", "putdown", "assemble"))
        seen.append((manip, [dict(s) for s in steps], out))
        return out

    monkeypatch.setattr(planning_run.PlanRun, "evaluate", evaluate)
    every = _exhaust(str(_problem("fabrica_stool_circular", ROOT)))["instances"]
    plan = _planner().plan(ROOT / "kb" / "problems" / "fabrica_stool_circular.yaml")
    assert plan.outcome.value == "plan"
    order = list(dict.fromkeys(m for m, _, _ in seen))
    first = [(steps, out) for m, steps, out in seen if m == order[0]]
    steps, out = first[-1]
    assert out["status"] == "infeasible", "the first instance went through: nothing to change"
    at = next(s for s in steps if s["id"] == out["at"])
    part = str(at["args"][0])
    g = _grasp(steps, part)
    same = [i for i in every if _grasp(i["steps"], part) == g]
    ids = [s["id"] for s in steps]
    assert same and all(i["status"] == "infeasible" and ids.index(i["at"]) <= ids.index(at["id"]) for i in same)
    assert all(len(i["steps"]) == len(ids) for i in same)
    assert any(i["status"] == "ok" for i in every if _grasp(i["steps"], part) != g)
    enumerated = [i for i in every if [s["id"] for s in i["steps"]] == [s["id"] for s in steps]]
    assert _grasp(enumerated[1]["steps"], part) == g  # partial_instances/2's next keeps the grasp
    second = next(steps for m, steps, _ in seen if m == order[1])
    assert _grasp(second, part) != g


def test_an_order_a_failure_needs_is_in_its_nogood(tmp_path: Path) -> None:
    """wide_pins' partial plan puts pin_b in first (phase 1 orders the two pickups); a grasp of pin_a
    that pin_b in place blocks goes in when pin_a is first. Each failing instance run with its two
    pickup-and-insert blocks swapped (an instance of no partial plan here, run all the same) gets
    past the failing step, and the failure's nogood does not rule it out: its order is part of it."""
    data = _exhaust(str(_problem("wide_pins", tmp_path)))
    cache = data["planner"].cache_of(data["cell"])
    failed = [i for i in data["instances"] if i["nogood"] is not None]
    assert failed
    for inst in failed:
        steps = inst["steps"]
        swapped = steps[2:] + steps[:2]
        assert [s["name"] for s in swapped] == ["pickup", "assemble", "pickup", "assemble"]
        ev = phase2.evaluate(cache, swapped, inst["sources"], [s["id"] for s in swapped])
        ids = [s["id"] for s in swapped]
        assert ev.status == "ok" or ids.index(ev.at) > ids.index(inst["at"]), (ev.status, ev.at)
        assert not _matches(inst["nogood"], inst["labels"], {**inst, "steps": swapped})
