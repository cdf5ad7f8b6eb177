"""Run every benchmark and write bench/RESULTS.md: ``python -m bench [--quick] [--out FILE]``.

The benchmarks are bench.ik (closed-form IK against Robotics Toolbox), bench.supinf
(SUP/INF tightness and time), bench.planning (the paper's cell warm and cold, the
generated N-peg problems), bench.fd (phase 1 against Fast Downward on the same
problems), bench.coldstart and bench.derive (object models derived from shapes and
meshes, issue 14), bench.products (the task board, issue 33), bench.fabrica (Fabrica's assemblies
derived from their meshes, issue 34); each also runs on its own
(``python -m bench.ik`` ...), and ``python -m bench --only products`` runs one and replaces its
section and target rows in RESULTS.md.
Figures are medians of repeated runs; every ratio compares two figures measured in the
same run, so machine noise affects both sides alike. ``--quick`` cuts the repeats and
sizes down to a smoke run of a minute or two (its figures are not for quoting).
"""
from __future__ import annotations

import argparse
import datetime as _dt
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

from . import coldstart, collision, derive, fabrica, fd, ik, memory, motion, planning, products, supinf

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "RESULTS.md"
#: The line after which RESULTS.md holds hand-written records (measurements of changes, choices
#: made and why): a new run writes its figures above it and keeps what follows.
RECORDS = "<!-- Records: written by hand, kept by python -m bench -->"

#: Issue 7's targets.
IK_US_PER_POSE = 5.0
IK_RATIO = 50.0
SUPINF_EXCESS = 0.01
SUPINF_MS_PER_BOUND = 5.0
WARM_S = 0.050
COLD_S = 0.6
N10_S = 2.0
#: Issue 18's targets: phase 1 at N = 20 and 50 (s, bench.fd.TARGETS); the whole plan at
#: N = 50 (s, MB).
PHASE1_TARGETS = fd.TARGETS
N50_S = 3.0
N50_MB = 200.0
#: Issue 12's target: RSS growth per plan after the warm-up (kB).
RSS_KB_PER_PLAN = memory.LIMIT_KB

#: Sizes of a full and a quick run.
FULL = {"ik": {"n": 10_000, "single": 1000, "rtb": 200, "repeats": 5}, "derive": {"repeats": 7},
        "supinf": {"per_length": 6, "repeats": 5},
        "planning": {"quick": False, "max_n": 10},
        "memory": {"plans": 1000, "warmup": 50},
        "coldstart": {"repeats": 15, "importtime_runs": 5},
        "fd": {"ns": fd.NS}, "motion": {"seeds": 10}, "collision": {"repeats": 5},
        "products": {"ns": products.NS, "repeats": products.REPEATS},
        "fabrica": {"repeats": fabrica.REPEATS}}
QUICK = {"ik": {"n": 1000, "single": 100, "rtb": 20, "repeats": 3}, "derive": {"repeats": 2},
         "supinf": {"per_length": 1, "lengths": (1, 4, 8), "repeats": 3, "deep_count": 2},
         "planning": {"quick": True, "max_n": 2, "timeout": 60.0},
         "memory": {"plans": 100, "warmup": 10, "processes": 1},
         "coldstart": {"repeats": 3, "importtime_runs": 1},
         "fd": {"ns": (1, 2)}, "motion": {"seeds": 2, "budget": 0.5},
         "collision": {"repeats": 1, "quick": True}, "products": {"ns": (5,), "repeats": 1},
         "fabrica": {"which": ["beam"], "repeats": 1}}


# ---------------------------------------------------------------------- where and with what


def machine() -> dict:
    """``uname -a``, the CPU model and the core count."""
    try:
        uname = subprocess.run(["uname", "-a"], capture_output=True, text=True, check=False).stdout.strip()
    except OSError:
        uname = " ".join(platform.uname())
    model = "unknown"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    try:
        load = " ".join(f"{x:.2f}" for x in os.getloadavg())
    except OSError:
        load = "unknown"
    return {"uname": uname, "cpu": model, "cores": os.cpu_count(), "load": load, "bytecode": bytecode()}


def bytecode() -> str:
    """How a cold process gets spar-py's bytecode: 'written' (Python caches it as usual),
    'compiled' (not written at import, PYTHONDONTWRITEBYTECODE, but compiled by set-up)
    or 'none' (every cold process compiles the sources)."""
    import importlib.util

    import spar_py.app.cli

    writes = not (sys.dont_write_bytecode or os.environ.get("PYTHONDONTWRITEBYTECODE"))
    if writes:
        return "written"
    pyc = Path(importlib.util.cache_from_source(spar_py.app.cli.__file__))
    return "compiled" if pyc.exists() else "none"


def versions() -> dict:
    """Python, numpy, casadi, SWI-Prolog (as recorded at set-up) and roboticstoolbox."""
    import casadi
    import numpy

    from spar_py.planning.engine import swipl_record

    try:
        import roboticstoolbox
        rtb = roboticstoolbox.__version__
    except ImportError:
        rtb = "not installed"
    rec = swipl_record()
    return {"python": platform.python_version(), "numpy": numpy.__version__,
            "casadi": casadi.__version__, "swipl": str(rec.get("version", "unknown")),
            "swipl_home": str(rec.get("home", "")), "roboticstoolbox": rtb}


# ---------------------------------------------------------------------- running


def run_all(quick: bool = False, log=None) -> dict:
    """Every benchmark, one after the other; the figures as one dict (what :func:`render` takes)."""
    say = log or (lambda line: None)
    sizes = QUICK if quick else FULL
    out: dict = {"quick": quick, "date": _dt.datetime.now().astimezone().isoformat(timespec="seconds"),
                 "machine": machine(), "versions": versions(), "seconds": {}}
    for name, fn in (("ik", lambda: ik.run(**sizes["ik"])),
                     ("supinf", lambda: supinf.run(**sizes["supinf"], progress=say)),
                     ("planning", lambda: planning.run(**sizes["planning"], progress=say)),
                     ("memory", lambda: memory.run(**sizes["memory"])),
                     ("coldstart", lambda: coldstart.run(**sizes["coldstart"])),
                     ("derive", lambda: derive.run(**sizes["derive"])),
                     ("fd", lambda: fd.run(**sizes["fd"], progress=say)),
                     ("motion", lambda: motion.run(**sizes.get("motion", {}))),
                     ("collision", lambda: collision.run(**sizes.get("collision", {}))),
                     ("products", lambda: products.run(**sizes["products"], progress=say)),
                     ("fabrica", lambda: fabrica.run(**sizes["fabrica"], progress=say))):
        say(f"== {name}")
        t = time.perf_counter()
        out[name] = fn()
        out["seconds"][name] = time.perf_counter() - t
    out["machine"]["load_after"] = machine()["load"]
    return out


# ---------------------------------------------------------------------- rendering


def _f(x, fmt: str = ".2f", none: str = "n/a") -> str:
    return none if x is None else format(x, fmt)


def table(head: list[str], rows: list[list[str]]) -> list[str]:
    return ["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|",
            *["| " + " | ".join(r) + " |" for r in rows], ""]


def _met(ok: bool) -> str:
    return "met" if ok else "NOT met"


def verdicts(r: dict) -> dict:
    """Each target of issue 7: (met?, the figure it was judged on, as text)."""
    k, s, p = r["ik"], r["supinf"], r["planning"]
    v: dict = {}
    v["ik_us"] = (k["batch_us"] <= IK_US_PER_POSE, f"{k['batch_us']:.2f} us/pose")
    ratio = k["rtb_over_batch"]
    v["ik_ratio"] = (ratio is not None and ratio >= IK_RATIO, f"{_f(ratio, '.0f')}x")
    if "ur" in k:  # issue 17: the UR closed form, all 8 branches
        ur_us = k["ur"]["ur5e"]["batch_us"]
        v["ur_ik_us"] = (ur_us <= IK_US_PER_POSE, f"{ur_us:.2f} us/pose (PUMA same run {k['batch_us']:.2f})")
    worst = max(s["paper"], key=lambda m: m["ours"])
    per_bound = max(m["t_ours"] / 2 for m in s["paper"])
    v["supinf_tight"] = (worst["ours"] <= SUPINF_EXCESS, f"{worst['ours']:.1e} of the width at worst")
    v["supinf_time"] = (per_bound <= SUPINF_MS_PER_BOUND, f"{per_bound:.2f} ms per bound at worst")
    if "deep" in s:  # issue 18: within 1% of the width up to depth 8, no box cap hit at +-0.1
        d = s["deep"]
        by_depth = max((x.get("worst", x["ours"]) for x in s.get("random", [])), default=0.0)
        worst_deep = d.get("worst", d["ours"])
        v["supinf_deep"] = (
            max(worst_deep, by_depth) <= SUPINF_EXCESS and d["capped"] == 0,
            f"depth 8 at +-0.1: {worst_deep:.1e} of the width at worst, cap hit {d['capped']}/{d['count']}; "
            f"random products depth 1-8: {by_depth:.1e} at worst (the same search on the SX alone, same "
            f"run: {_f(d.get('sx_worst'), '.1e')} at worst, cap hit {d.get('sx_capped', '?')}/{d['count']}; on "
            f"the SX as composed: {_f(d.get('old_worst'), '.1e')}, cap hit {d.get('old_capped', '?')}/{d['count']})")
    v["warm"] = (p["warm"]["wall_s"] < WARM_S, f"{p['warm']['wall_s'] * 1e3:.0f} ms")
    v["cold"] = (p["cold"]["plan_s"] < COLD_S, f"{p['cold']['plan_s']:.2f} s")
    n10 = next((x for x in p["scaling"] if x["n"] == 10), None)
    if n10 is None:
        v["n10"] = (False, "not run")
    else:
        ok = n10.get("outcome") == "plan" and n10.get("wall_s", 1e9) < N10_S
        v["n10"] = (ok, f"{n10.get('outcome')} after {_f(n10.get('wall_s'))} s")
    for n, limit in PHASE1_TARGETS.items():
        x = next((x for x in r.get("fd", []) if x["n"] == n), None)
        t = None if x is None else x["ours"].get("first_s")
        fdp = None if x is None else x["fd"].get("planner_s")
        v[f"phase1_n{n}"] = (t is not None and t <= limit,
                             "not run" if t is None else f"{t:.3f} s (FD lama-first {_f(fdp, '.3f')} s, same run)")
    n50 = next((x for x in p["scaling"] if x["n"] == 50), None)
    if n50 is not None:
        ok = (n50.get("outcome") == "plan" and n50.get("wall_s", 1e9) <= N50_S
              and n50.get("rss_peak_mb", 1e9) <= N50_MB)
        v["n50"] = (ok, f"{n50.get('outcome')} after {_f(n50.get('wall_s'))} s, "
                        f"peak RSS {_f(n50.get('rss_peak_mb'), '.0f')} MB")
    for row in r.get("memory", []):
        runs = row.get("runs", [row["kb_per_plan"]])
        v[f"rss_{row['cell']}"] = (row["kb_per_plan"] <= RSS_KB_PER_PLAN,
                                   f"{row['kb_per_plan']:.2f} kB/plan over {row['plans']} plans (median of "
                                   f"{len(runs)} processes: {', '.join(f'{x:.2f}' for x in runs)})")
    return v


def render(r: dict) -> str:
    """RESULTS.md from :func:`run_all`'s dict."""
    m, ver, k, s, p = r["machine"], r["versions"], r["ik"], r["supinf"], r["planning"]
    v = verdicts(r)
    L = ["# spar-py benchmarks", "",
         f"Written by `python -m bench{' --quick' if r['quick'] else ''}` on {r['date']}"
         + (" (a QUICK run: small sizes, figures not for quoting)." if r["quick"] else "."),
         "Figures are medians of repeated runs; ratios compare figures measured in the same run.", "",
         "## Machine and versions", "",
         f"- `{m['uname']}`",
         (f"- CPU: {m['cpu']}, {m['cores']} cores; load average {m['load']} before, "
         f"{m.get('load_after', '?')} after (a shared, noisy machine)"),
         (f"- Python {ver['python']}, numpy {ver['numpy']}, casadi {ver['casadi']}, "
         f"SWI-Prolog {ver['swipl']}, roboticstoolbox-python {ver['roboticstoolbox']}"),
         ("- Python bytecode cache: "
          + {"written": "written as usual",
             "compiled": "not written at import (PYTHONDONTWRITEBYTECODE is set); compiled by `make setup`",
             "none": "off (PYTHONDONTWRITEBYTECODE is set and nothing compiled, so every cold process "
                     "compiles spar-py's sources)"}.get(str(m.get("bytecode", "written")), "unknown")),
         "- time spent: " + ", ".join(f"{n} {t:.0f} s" for n, t in r["seconds"].items()), "",
         "## Targets (issue 7)", ""]
    L += table(["target", "measured", "verdict"], [
        [f"IK, all solutions, batch <= {IK_US_PER_POSE:g} us/pose", v["ik_us"][1], _met(v["ik_us"][0])],
        [f"IK >= {IK_RATIO:g}x RTB ikine_a per pose", v["ik_ratio"][1], _met(v["ik_ratio"][0])],
        ["SUP/INF within 1% of the true range (paper's expressions)", v["supinf_tight"][1],
         _met(v["supinf_tight"][0])],
        [f"SUP/INF <= {SUPINF_MS_PER_BOUND:g} ms per bound (paper's expressions)", v["supinf_time"][1],
         _met(v["supinf_time"][0])],
    ] + ([["SUP/INF within 1% of the width up to depth 8, no box cap hit (issue 18)", v["supinf_deep"][1],
           _met(v["supinf_deep"][0])]] if "supinf_deep" in v else []) + [
        [f"paper's cell warm < {WARM_S * 1e3:g} ms", v["warm"][1], _met(v["warm"][0])],
        [f"paper's cell cold < {COLD_S:g} s", v["cold"][1], _met(v["cold"][0])],
        [f"N = 10 planned under {N10_S:g} s", v["n10"][1], _met(v["n10"][0])],
    ] + [[f"phase 1 at N = {n} <= {limit:g} s (issue 18)", v[f"phase1_n{n}"][1], _met(v[f"phase1_n{n}"][0])]
         for n, limit in PHASE1_TARGETS.items()
    ] + ([[f"whole plan at N = 50 <= {N50_S:g} s and {N50_MB:g} MB (issue 18)", v["n50"][1], _met(v["n50"][0])]]
         if "n50" in v else []
    ) + ([[f"UR IK, all 8 branches, batch <= {IK_US_PER_POSE:g} us/pose (issue 17)", v["ur_ik_us"][1],
           _met(v["ur_ik_us"][0])]] if "ur_ik_us" in v else []
    ) + coldstart.target_rows(r.get("coldstart")) + products.target_rows(r.get("products"))
      + fabrica.target_rows(r.get("fabrica")) + [
        [f"RSS growth, {name}, <= {RSS_KB_PER_PLAN:g} kB per plan (issue 12)", v[key][1], _met(v[key][0])]
         for key, name in (("rss_paper", "paper's cell"), ("rss_n3", "generated N = 3"))
         if key in v])
    L += ["## Reading", "", reading(r), ""]

    L += ["## IK (bench/ik.py)", "",
          (f"PUMA 762 closed form (spar-py) against Robotics Toolbox's analytic `Puma560().ikine_a`; "
          f"microseconds per pose, median of {k['repeats']} runs."), ""]
    rows = [["spar-py `ik_batch` (all solutions, one call)", str(k["n"]), _f(k["batch_us"]), "1"],
            ["spar-py `ik` (all solutions, one call per pose)", str(k["n_single"]), _f(k["single_us"]),
             _f(k["single_us"] / k["batch_us"], ".1f")]]
    if k["rtb_us"] is not None:
        rows += [["RTB `ikine_a` (one configuration per call)", str(k["n_rtb"]), _f(k["rtb_us"]),
                  _f(k["rtb_over_batch"], ".1f")],
                 ["RTB `ikine_a` x 8 (all configurations)", str(k["n_rtb"]), _f(k["rtb_all8_us"]),
                  _f(k["rtb_all8_over_batch"], ".1f")]]
    L += table(["method", "poses", "us/pose", "x ik_batch"], rows)
    L += [f"Solutions per pose (rows within joint limits): {k['solutions_per_pose']:.1f}. "
          + ("" if k["rtb_us"] is None else
             f"RTB `ikine_a` / spar-py `ik` one call per pose: {k['rtb_over_single']:.1f}x "
             f"(all eight configurations: {k['rtb_all8_over_single']:.1f}x)."), ""]

    if "ur" in k:
        u = k["ur"]
        L += ["### UR family and the numeric fallback (issue 17)", "",
              ("UR closed form (Hawkins 2013) on the UR5e file and on RTB's own UR5 table; RTB has no "
               "analytic UR solver, so its peer is `UR5().ikine_LM` (numeric, one configuration per call). "
               f"Microseconds per pose, median of {k['repeats']} runs, same run as the PUMA rows."), ""]
        rows = [[f"spar-py UR `ik_batch` ({name}, all 8 branches, one call)", str(k["n"]), _f(u[name]["batch_us"]),
                 _f(u[name]["branches_per_pose"], ".1f")] for name in ("ur5e", "ur5")]
        rows += [[f"spar-py UR `ik` ({name}, every turn representation, one call per pose)", str(k["n_single"]),
                  _f(u[name]["single_us"]), _f(u[name]["rows_per_pose"], ".0f")] for name in ("ur5e",)]
        if u["rtb_lm_us"] is not None:
            rows.append(["RTB UR5 `ikine_LM` (one configuration per call)", str(max(1, k["n_rtb"] // 4)),
                         _f(u["rtb_lm_us"]), "1"])
        m = k["numeric"]
        rows.append([f"spar-py numeric `ik_batch` (PUMA with d5 = 95 mm; {m['solved']:.0%} solved, own q "
                     f"found {m['own_found']:.0%})", str(m["n"]), _f(m["batch_us"]),
                     _f(m["solutions_per_pose"], ".1f")])
        L += table(["method", "poses", "us/pose", "solutions/pose"], rows)
        if u["rtb_lm_over_batch"] is not None:
            L += [f"RTB UR5 `ikine_LM` / spar-py UR5 `ik_batch`: {u['rtb_lm_over_batch']:.0f}x.", ""]

    L += ["## SUP/INF (bench/supinf.py)", "",
          ("Excess of a bound over the true range as a fraction of the true width (the true range: "
          "20 000 samples + IPOPT, an inner bound); `ours` is `Bounder.bounds` (both ends, refined to "
          "1e-3 of the width), `plain` one pass of interval arithmetic (the paper's SUP/INF as "
          "described); times in ms, medians; `1-side` is one bound with its compile, as the planner "
          "spends it; `reached` counts expressions refined to the tolerance."), "",
          "### The paper's cell", ""]
    L += table(["expression", "vars", "ours/w", "plain/w", "reached", "ours ms (2 bounds)",
                 "1-side ms", "compile ms", "plain ms", "INF", "SUP"],
                [[x["name"], str(x["n_vars"]), _f(x["ours"], ".1e"), _f(x["plain"], ".1e"),
                  "yes" if x["reached"] else "no", _f(x["t_ours"]), _f(x["t_one"]), _f(x["t_compile"]),
                  _f(x["t_plain"], ".3f"), _f(x["lo"], ".4f"), _f(x["hi"], ".4f")] for x in s["paper"]])
    for g, title in (("plan_like", "Plan-like expressions (random plans on the paper's cell)"),
                     ("random", "Random HTM products")):
        if g not in s:
            continue
        L += [f"### {title}, {s['per_length']} per length", ""]
        L += table(["plan length", "vars", "ours/w", "plain/w", "reached", "ours ms", "1-side ms",
                     "compile ms", "plain ms"],
                    [[str(x["length"]), f"{x['n_vars']:.0f}", _f(x["ours"], ".1e"), _f(x["plain"], ".1e"),
                      f"{x['reached']}/{x['count']}", _f(x["t_ours"]), _f(x["t_one"]), _f(x["t_compile"]),
                      _f(x["t_plain"], ".3f")] for x in s[g]])
    if "deep" in s:
        d = s["deep"]
        L += [f"### Products of depth 8 at +-0.1 (in, rad), {d['count']} expressions", ""]
        L += ["`ours` bounds each product as a chain expression (symbolic.ChainExpr: the search, and point "
              "sets through the chain once it has evaluated 512 boxes); `SX alone` is the same search on the "
              "chain's SX, without the chain; `SX as composed` the same search on the SX a caller gets by "
              "composing SX matrices (T^-1 p through `inv` of the whole product, not the factors' inverses; "
              "this table's expressions before chains); all in the same run. The second row, beyond the "
              "target, has every angle at +-1 rad (the point sets' budget then widens their arcs' segments).",
              ""]

        def deep_row(label: str, d: dict) -> list[str]:
            return [label, f"{d['n_vars']:.0f}", f"{_f(d['ours'], '.1e')}, {_f(d.get('worst'), '.1e')}",
                    f"{_f(d.get('sx_ours'), '.1e')}, {_f(d.get('sx_worst'), '.1e')}",
                    f"{_f(d.get('old_ours'), '.1e')}, {_f(d.get('old_worst'), '.1e')}", _f(d["plain"], ".1e"),
                    f"{d['reached']}/{d['count']}, {d.get('sx_reached', '?')}/{d['count']}, "
                    f"{d.get('old_reached', '?')}/{d['count']}",
                    f"{d['capped']}/{d['count']}, {d.get('sx_capped', '?')}/{d['count']}, "
                    f"{d.get('old_capped', '?')}/{d['count']} (cap {d['max_boxes']})",
                    f"{d['boxes_median']:.0f}, {d['boxes_max']}", _f(d["t_ours"]), _f(d.get("t_sx")),
                    _f(d.get("t_old")), _f(d["t_cached"], ".3f"),
                    f"{_f(d['t_compiled'])} ({_f(d['t_compiled_first'], '.0f')})",
                    _f(d["t_compile"]), _f(d["t_plain"], ".3f")]

        rows = [deep_row("+-0.1", d)] + ([deep_row(f"+-0.1, angles +-1 ({s['deep_wide']['count']})",
                                                     s["deep_wide"])] if "deep_wide" in s else [])
        L += table(["products", "vars", "ours/w (median, worst)", "SX alone/w (median, worst)",
                     "SX as composed/w (median, worst)", "plain/w", "reached (ours, SX alone, as composed)",
                     "box cap hit (ours, SX alone, as composed)", "boxes (median, max)", "ours ms",
                     "SX alone ms", "SX as composed ms", "cached ms", "compiled=True ms (first)",
                     "compile ms", "plain ms"], rows)
    L += [(f"`uncertainty.evaluate` on the first pickup's four constraints: {s['evaluate_ms']:.2f} ms per "
          f"constraint. Unsound bounds (inside the sampled range): {s['unsound']}."), ""]

    w, c = p["warm"], p["cold"]
    L += ["## Planning (bench/planning.py)", "",
          "### The paper's cell (kb/problems/peg_in_block.yaml)", "",
          (f"Warm: `Planner().plan(...)` in one process, {w['repeats']} runs after one warm-up "
          "(phase times are Prolog CPU time from `plan.timing`, Python called back included; "
          "`load_problem` timed alone between the runs). Cold: `spar plan` as a fresh process, "
          f"{c['repeats']} runs, interleaved with a process that only starts the engine."), ""]
    L += table(["figure", "median", "ratio"], [
        ["warm: phase 1", f"{w['phase1_s'] * 1e3:.1f} ms", f"{w['phase1_s'] / w['wall_s']:.2f} of wall"],
        ["warm: phase 2", f"{w['phase2_s'] * 1e3:.1f} ms", f"{w['phase2_s'] / w['wall_s']:.2f} of wall"],
        ["warm: `load_problem` alone (YAML)", f"{w['load_s'] * 1e3:.1f} ms",
         f"{w['load_s'] / w['wall_s']:.2f} of wall"],
        ["warm: wall of `plan()`", (f"{w['wall_s'] * 1e3:.1f} ms "
         f"(min {w['min_wall_s'] * 1e3:.0f}, max {w['max_wall_s'] * 1e3:.0f})"), "1"],
        ["cold: `spar plan`", f"{c['plan_s']:.3f} s", f"{c['ratio']:.2f}x engine start"],
        ["cold: engine start only", f"{c['start_s']:.3f} s", "1"],
        ["cold: plan minus start", f"{c['plan_minus_start_s']:.3f} s", ""],
    ])
    if "hopeless" in p:
        h = p["hopeless"]
        L += table(["hopeless_uncertainty.yaml (cold, interleaved)", "median", "ratio"], [
            ["`spar plan`", f"{h['plan_s']:.2f} s", f"{h['plan_s'] / h['paper_s']:.1f}x the paper's cell"],
            ["`spar plan --phase1-only`", f"{h['phase1_only_s']:.2f} s", ""],
            ["phase 2 (difference)", f"{h['phase2_s']:.2f} s", ""],
            ["the paper's cell", f"{h['paper_s']:.2f} s", "1"],
        ]) + [""]
    L += [(f"Outcome {w['outcome']}, {w['actions']} actions, {w['instances_examined']} instance(s) "
          f"examined; process exit codes {c['returncodes']}."), ""]

    L += ["### Generated problems: N pegs into N blocks (spar_py.app.gen)", "",
          (f"One subprocess per N, a warm-up plan of the paper's cell first; "
          f"`Planner(timeout={p['timeout_s']:g})` with phase 1's default bound, derived from the problem "
          "(up to 42 pairs the blocks start hole-down and each is turned over, up to 70 on a side face "
          "and each is turned a quarter turn: 4N actions; above, the blocks start hole-up: 2N actions, see "
          "spar_py.app.gen.blocks_for; the bound is derived from the problem). "
          "Times: phase 1/2 are Prolog CPU seconds, wall the "
          "`plan()` call; RSS (Python and the embedded Prolog share the process): 'before' after the "
          "warm-up, 'peak' sampled every 5 ms while planning (getrusage's maxrss is not used: on Linux "
          "a child keeps its parent's high-water mark across exec). "
          "Profiles below are of a separate child's first plan of that N."), ""]
    rows = []
    for x in p["scaling"]:
        why = ""
        if x.get("outcome") == "no_plan":
            why = "step budget spent" if x.get("budget_spent") else "no plan within the bound"
            reason = x.get("reason") or {}
            if reason.get("max_actions") is not None:
                why += f" (at bound {reason['max_actions']})"
        elif x.get("outcome") == "error":
            why = x.get("error", "")
        rows.append([str(x["n"]), str(x["max_actions"]), str(x.get("outcome")), _f(x.get("phase1_s"), ".3f"),
                     _f(x.get("phase2_s"), ".3f"), _f(x.get("wall_s"), ".3f"), _f(x.get("actions"), "d"),
                     _f(x.get("instances_examined"), "d"), _f(x.get("rss_before_mb"), ".0f"),
                     _f(x.get("rss_peak_mb"), ".0f"), _f(x.get("prolog_stack_mb"), ".1f"), why])
    L += table(["N", "max_actions", "outcome", "phase 1 s", "phase 2 s", "wall s", "actions", "instances",
                 "RSS before MB", "RSS peak MB", "Prolog stacks MB", "note"], rows)

    if r.get("fd"):
        L += ["## Phase 1 against Fast Downward (bench/fd.py)", "",
              ("The generated problems again, each planned by our phase 1 (default options; Prolog CPU "
               "seconds: `first` computes the reachability arcs, `warm` is the median of 3 more runs "
               "with them memoised) and, in the same run, by Fast Downward `--alias lama-first` on the "
               "PDDL encoding bench/fd.py writes from the same cell (the arcs as static facts; FD's "
               "`search` and `planner` times are its own, `planner` includes its translator; `wall` is "
               "its driver process)."), ""]
        L += fd.table(r["fd"])

    if r.get("products"):
        L += products.render(r["products"])

    if r.get("fabrica"):
        L += fabrica.render(r["fabrica"])

    if r.get("memory"):
        L += ["## Memory per plan (bench/memory.py)", "",
              ("Each cell in 3 fresh processes (the median is the figure; each process's figure beside it): "
               "planned by path with one Planner, "
               f"{r['memory'][0]['warmup']} warm-up plans, then {r['memory'][0]['plans']} more; "
               "growth = (RSS after - RSS after the warm-up) / plans, RSS after `gc.collect()`; "
               "live objects counted after the run."), ""]
        L += table(["cell", "plans", "RSS after warm-up MB", "RSS after MB", "kB per plan (median)",
                     "each process", "live Cell", "live World"],
                    [[x["cell"], str(x["plans"]), f"{x['rss_before_kb'] / 1024:.1f}",
                      f"{x['rss_after_kb'] / 1024:.1f}", f"{x['kb_per_plan']:.2f}",
                      ", ".join(f"{k:.2f}" for k in x.get("runs", [x["kb_per_plan"]])),
                      str(x["live"]["Cell"]), str(x["live"]["World"])] for x in r["memory"]])

    if r.get("before_after"):
        ba = r["before_after"]
        L += ["## Before and after (bench/before_after.py)", "",
              (f"This checkout against `{ba['dir']}` (commit {ba['commit']}), measured in the same run: "
               "cold `spar plan` of the paper's cell, the two checkouts alternating; warm, the median plan "
               "of one process per checkout. Medians."), ""]
        L += table(["figure", "before", "after", "after/before"],
                    [[name, f"{v['before'] * 1e3:.1f} ms", f"{v['after'] * 1e3:.1f} ms",
                      f"{v['after'] / v['before']:.2f}"] for name, v in ba["figures"].items()])

    if r.get("coldstart"):
        L += coldstart.render(r["coldstart"])
    if "derive" in r:
        L += derive.markdown(r["derive"])
    if r.get("motion"):
        L += motion.render(r["motion"])
    if r.get("collision"):
        L += collision.render(r["collision"])

    L += ["## Where the time goes (cProfile)", "",
          ("Python's profiler sees SWI-Prolog as one call (`janus_swi._swipl.call`): its internal time "
          "is Prolog's own work, its cumulative time includes the Python called back from Prolog "
          "(reachability, IK, placements, SUP/INF). Profiling inflates pure-Python code (YAML) most."), "",
          "### The paper's cell, warm", "", "```", w.get("profile", "(not profiled)"), "```", ""]
    prof = [x for x in p["scaling"] if "profile" in x]
    for x in prof:
        L += [f"### Generated N = {x['n']} (the largest N that finished; outcome {x['outcome']})", "",
              "```", x["profile"], "```", ""]
    return "\n".join(L).rstrip() + "\n"


def _prolog_share(profile_text: str) -> tuple[float, float] | None:
    """(Prolog's own seconds, the profiled total) from a profile's text, if it shows them."""
    total = own = None
    for line in profile_text.splitlines():
        if "function calls" in line and " in " in line:
            total = float(line.rsplit(" in ", 1)[1].split()[0])
        if "janus_swi._swipl.call" in line and own is None:
            own = float(line.split()[1])
    return (own, total) if own is not None and total else None


def reading(r: dict) -> str:
    """The one-paragraph reading of the figures against the targets."""
    k, s, p = r["ik"], r["supinf"], r["planning"]
    v = verdicts(r)
    w, c = p["warm"], p["cold"]
    parts = []
    parts.append(
        f"IK: the batch solver gives all solutions in {k['batch_us']:.2f} us/pose "
        f"({_met(v['ik_us'][0])} against {IK_US_PER_POSE:g} us)"
        + ("" if k["rtb_over_batch"] is None else
           f", {k['rtb_over_batch']:.0f}x faster per pose than one RTB `ikine_a` call and "
           f"{k['rtb_all8_over_batch']:.0f}x than the eight calls RTB needs for all solutions "
           f"({_met(v['ik_ratio'][0])} against {IK_RATIO:g}x); called one pose at a time spar-py's `ik` is "
           f"only {k['rtb_over_single']:.1f}x RTB, so the speed is numpy batching, not the arithmetic")
        + ".")
    worst_plain = max(x["plain"] for x in s["paper"])
    parts.append(
        f"SUP/INF on the paper's expressions: {v['supinf_tight'][1]} ({_met(v['supinf_tight'][0])}), "
        f"{v['supinf_time'][1]} ({_met(v['supinf_time'][0])}; one bound with its compile, as the planner "
        f"pays it, {max(x['t_one'] for x in s['paper']):.1f} ms at worst), where plain interval arithmetic "
        f"overshoots by up to {worst_plain:.1e} of the width; {s['unsound']} unsound bound(s).")
    share = _prolog_share(w.get("profile", ""))
    where = ""
    if share:
        where = (f" Under the profiler Prolog's own work is {share[0] * 1e3:.0f} ms of "
                 f"{share[1] * 1e3:.0f} ms: the rest is Python called back from Prolog "
                 "(reachability arcs, placements, phase 2's SUP/INF bounds) and reading the YAML "
                 f"({w['load_s'] * 1e3:.0f} ms of each warm run).")
    parts.append(
        f"Planning the paper's cell warm takes {w['wall_s'] * 1e3:.0f} ms "
        f"(phase 1 {w['phase1_s'] * 1e3:.0f} ms, phase 2 {w['phase2_s'] * 1e3:.0f} ms): "
        f"{_met(v['warm'][0])} against {WARM_S * 1e3:g} ms; cold `spar plan` takes {c['plan_s']:.2f} s "
        f"({_met(v['cold'][0])} against {COLD_S:g} s), of which starting Python and the engine alone is "
        f"{c['start_s']:.2f} s ({c['start_s'] / c['plan_s']:.0%})." + where
        + " The warm repeats plan the same cell again, so they find the memo tables (keyed on the "
        "cell's content) filled by the run before; a first plan of a new cell on a warm engine is "
        "the N = 1 row of the scaling table.")
    sc = p["scaling"]
    planned = [x["n"] for x in sc if x.get("outcome") == "plan"]
    other = [f"N = {x['n']} {x.get('outcome')}" + (" (step budget)" if x.get("budget_spent") else "")
             for x in sc if x.get("outcome") != "plan"]
    largest = max((x for x in sc if x.get("outcome") == "plan"), key=lambda x: x["n"], default=None)
    txt = (f"Scaling: the generated problems were planned for N = {planned or 'none'}"
           + (f" (N = {largest['n']} in {largest['wall_s']:.2f} s)" if largest else "")
           + ("; " + ", ".join(other) if other else "")
           + f"; the N = 10 target ({N10_S:g} s) is {_met(v['n10'][0])} ({v['n10'][1]}).")
    parts.append(txt)
    if r["quick"]:
        parts.append("(A quick run: the sizes are too small for these figures to be quoted.)")
    return " ".join(parts)


#: The benchmarks ``--only`` runs alone: name -> (run at the full or quick sizes, splice into RESULTS.md).
ONLY = {"products": (lambda quick, say: products.run(**(QUICK if quick else FULL)["products"], progress=say),
                     products.splice),
        "fabrica": (lambda quick, say: fabrica.run(**(QUICK if quick else FULL)["fabrica"], progress=say),
                    fabrica.splice)}


def only(name: str, quick: bool = False, out: Path | None = None) -> None:
    """``python -m bench --only NAME``: that benchmark alone; its section and target rows replace
    theirs in RESULTS.md (or ``out``; with ``quick`` and no ``out``, printed), the rest kept."""
    run_one, splice = ONLY[name]
    r = run_one(quick, lambda line: print(line, file=sys.stderr, flush=True))
    target = out if out is not None else (None if quick else RESULTS)
    old = target.read_text(encoding="utf-8") if target is not None and target.exists() else ""
    text = splice(old, r)
    if target is None:
        print(text)
        return
    target.write_text(text, encoding="utf-8")
    print(f"wrote {target}", file=sys.stderr)


def _commit(root: Path) -> str:
    """The short commit of checkout ``root`` (or "?")."""
    try:
        return subprocess.run(["git", "-C", str(root), "rev-parse", "--short", "HEAD"], capture_output=True,
                              text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "?"


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(prog="python -m bench", description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="a short smoke run (fewer repeats, N = 1..2)")
    ap.add_argument("--out", type=Path, default=None,
                    help="where to write the results (default bench/RESULTS.md; with --quick, stdout only)")
    ap.add_argument("--before", type=Path, default=None, metavar="DIR",
                    help="also time warm and cold planning against the checkout DIR (bench/before_after.py)")
    ap.add_argument("--only", choices=tuple(ONLY), default=None,
                    help="run this benchmark alone and replace its section and target rows in the results")
    a = ap.parse_args(argv)
    if a.only is not None:
        only(a.only, a.quick, a.out)
        return
    r = run_all(a.quick, log=lambda line: print(line, file=sys.stderr, flush=True))
    if a.before is not None:
        from . import before_after

        r["before_after"] = {"dir": str(a.before), "commit": _commit(a.before),
                             "figures": before_after.run(a.before.resolve(), 5 if a.quick else 15)}
    text = render(r)
    out = a.out if a.out is not None else (None if a.quick else RESULTS)
    if out is None:
        print(text)
    else:
        old = out.read_text(encoding="utf-8") if out.exists() else ""
        if RECORDS in old:
            text = text.rstrip("\n") + "\n\n" + RECORDS + old.split(RECORDS, 1)[1]
        out.write_text(text, encoding="utf-8")
        print(f"wrote {out}", file=sys.stderr)
        print(text.split("## IK")[0])


if __name__ == "__main__":
    main()
