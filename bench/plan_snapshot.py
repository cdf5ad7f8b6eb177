"""Snapshot every kb/problems plan's JSON (steps, verdicts, joints, poses, reasons) and compare
two snapshots: the check that a refactor changed no plan (a key renamed between schemas, listed
in RENAMED, and the schema number itself are not differences).

    python -m bench.plan_snapshot write DIR [PROBLEMS_DIR]   # one JSON per problem, timing removed
    python -m bench.plan_snapshot compare OLD_DIR NEW_DIR    # exit 1 and name each difference

Only the public API (``spar_py.Planner``) is used, so the same script runs on the commits
before and after a change. Motions are planned where a problem file asks (the regression's
options); their waypoints are compared too. Floats are compared exactly.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

#: Keys of a plan's JSON that a refactor may change without changing the plan.
VOLATILE = {"timing", "time_s", "seconds", "elapsed_s", "total_s", "planning_s"}


def _strip(v: Any) -> Any:
    if isinstance(v, dict):
        return {k: _strip(x) for k, x in v.items() if k not in VOLATILE}
    if isinstance(v, list):
        return [_strip(x) for x in v]
    return v


def write(out: Path, problems: Path) -> None:
    from spar_py import Planner
    from spar_py.core.errors import SparError

    out.mkdir(parents=True, exist_ok=True)
    for f in sorted(problems.glob("*.yaml")):
        try:
            plan = Planner().plan(f)
        except SparError as e:  # a cell that does not load is a difference to show, not a crash
            (out / f"{f.stem}.json").write_text(json.dumps({"error": str(e)}, indent=1))
            print(f"{f.stem}: error: {e}", flush=True)
            continue
        doc = _strip(plan.to_json())
        (out / f"{f.stem}.json").write_text(json.dumps(doc, indent=1, sort_keys=True))
        print(f"{f.stem}: {plan.outcome.value}", flush=True)


def _diff(a: Any, b: Any, path: str, out: list[str]) -> None:
    if len(out) > 20:
        return
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b)):
            if k not in a or k not in b:
                out.append(f"{path}.{k}: only in {'new' if k in b else 'old'}")
            else:
                _diff(a[k], b[k], f"{path}.{k}", out)
    elif isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            out.append(f"{path}: {len(a)} items against {len(b)}")
        for i, (x, y) in enumerate(zip(a, b)):
            _diff(x, y, f"{path}[{i}]", out)
    elif a != b:
        out.append(f"{path}: {a!r} against {b!r}")


#: Keys renamed between plan JSON schemas, old name -> new (docs/json-schema.md): a snapshot of an
#: older schema is read with the new names, so a rename alone is no difference.
RENAMED = {2: {"from": "source"}}


def _upgrade(doc: Any, renamed: dict[str, str]) -> Any:
    if isinstance(doc, dict):
        return {renamed.get(k, k): _upgrade(v, renamed) for k, v in doc.items()}
    if isinstance(doc, list):
        return [_upgrade(x, renamed) for x in doc]
    return doc


def _read(path: Path) -> Any:
    doc = json.loads(path.read_text())
    return _upgrade({k: v for k, v in doc.items() if k != "schema"}, RENAMED.get(doc.get("schema"), {}))


def compare(old: Path, new: Path) -> int:
    bad = 0
    for f in sorted(old.glob("*.json")):
        g = new / f.name
        if not g.exists():
            print(f"{f.stem}: missing in {new}")
            bad += 1
            continue
        out: list[str] = []
        _diff(_read(f), _read(g), f.stem, out)
        print(f"{f.stem}: {'same' if not out else 'DIFFERENT'}")
        for line in out:
            print("   ", line)
        bad += bool(out)
    return 1 if bad else 0


if __name__ == "__main__":
    if len(sys.argv) >= 3 and sys.argv[1] == "write":
        write(Path(sys.argv[2]), Path(sys.argv[3] if len(sys.argv) > 3 else "kb/problems"))
    elif len(sys.argv) == 4 and sys.argv[1] == "compare":
        sys.exit(compare(Path(sys.argv[2]), Path(sys.argv[3])))
    else:
        sys.exit(__doc__)
