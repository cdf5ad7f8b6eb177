"""Dump what a Fabrica assembly's cold load derives, to compare two checkouts' results exactly.

``python -m bench.fabrica_dump PRODUCT.yaml OUT.json`` (set ``SPAR_CACHE_DIR`` to an empty
directory for a cold load): the product's outcome, the assembly derivation (mates, seats,
blocking contacts, insertions, precedence, rounded to 1e-6), each mesh part's derived object
model (stable poses: R, height, resting faces; grasps: T, width, faces; face names) and, for a
product that loads, every part's poses (subassembly poses included) and grasps as the planner
sees them. Two runs' files are equal when the derivations are (``cmp``); bench/fabrica.py's
product files (or any mesh-only product) are the input.
"""
from __future__ import annotations

import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np


def _r(x: Any) -> list:
    return np.round(np.asarray(x, float), 6).tolist()


def _rr(o: Any) -> Any:
    if isinstance(o, float):
        return round(o, 6)
    if isinstance(o, list):
        return [_rr(x) for x in o]
    if isinstance(o, dict):
        return {k: _rr(v) for k, v in o.items()}
    return o


def dump(product: Path) -> dict:
    """The derivation of ``product`` as plain data (module docstring)."""
    import spar_py.world.product.assembly as wa
    from spar_py.kb import products as kp
    from spar_py.kb.objects import load_object

    cap: dict[str, Any] = {}
    objects, derive = kp._derived_objects, wa.derive_assembly

    def keep_objects(*a: Any, **k: Any) -> Any:
        cap["objects"] = (r := objects(*a, **k))[0]
        return r

    def keep_derived(*a: Any, **k: Any) -> Any:
        cap["derived"] = r = derive(*a, **k)
        return r
    kp._derived_objects, wa.derive_assembly = keep_objects, keep_derived  # type: ignore[assignment]
    try:
        lp = kp.load_product_derived(product, "mm")
        outcome = "ok"
    except Exception as e:  # noqa: BLE001 - a refusal is a result to compare
        lp, outcome = None, "REFUSED: " + str(e)
    d: dict[str, Any] = {"outcome": outcome}
    if "derived" in cap:
        j = cap["derived"].to_json()
        j.pop("seconds")
        d["derived"] = _rr(json.loads(json.dumps(j, default=float)))
    parts: dict[str, Any] = {}
    for p, text in sorted(cap.get("objects", {}).items()):
        try:
            m = load_object(kp._generated(text), "mm")
            parts[p] = {"poses": {k: [_r(v.R), round(v.height, 6), [str(x) for x in v.rfaces]]
                                  for k, v in sorted(m.poses.items())},
                        "grasps": {k: [_r(g.T), round(g.width, 6), [str(x) for x in g.gfaces]]
                                   for k, g in sorted(m.grasps.items())},
                        "faces": sorted(map(str, m.faces))}
        except Exception as e:  # noqa: BLE001
            parts[p] = "REFUSED: " + str(e)
    d["parts"] = parts
    if lp is not None:
        d["product_parts"] = {p: {"poses": {k: [_r(v.R), round(v.height, 6), [str(x) for x in v.rfaces]]
                                            for k, v in sorted(pp.model.poses.items())},
                                  "grasps": {k: [_r(g.T), round(g.width, 6)]
                                             for k, g in sorted(pp.model.grasps.items())}}
                              for p, pp in lp.product.parts.items()}
        d["precedence"] = [str(x) for x in lp.product.precedence]
        d["mates"] = [str(x) for x in lp.product.mates]
        d["seats"] = [str(x) for x in lp.product.seats]
    return d


def main(argv: list[str] | None = None) -> None:
    a = sys.argv[1:] if argv is None else argv
    if len(a) != 2:
        sys.exit("usage: python -m bench.fabrica_dump PRODUCT.yaml OUT.json")
    t = time.perf_counter()
    d = dump(Path(a[0]))
    Path(a[1]).write_text(json.dumps(d, indent=1, sort_keys=True), encoding="utf-8")
    print(f"{a[0]}: {d['outcome'][:100]} ({time.perf_counter() - t:.2f} s)")


if __name__ == "__main__":
    main()
