"""The ``spar`` command.

Exit codes (EXIT_CODES, also in ``spar --help`` and the README): 0 a plan; 1 no plan
or a failed check; 2 bad input (a knowledge-base file, an argument, an output that
cannot be written); 3 an internal error (a bug); 4 timeout; 130 Ctrl-C; 143 SIGTERM.
Errors are one line on stderr, never a traceback.
"""
from __future__ import annotations

import argparse
import atexit
import gc
import json
import os
import sys
import threading
from pathlib import Path
from typing import Callable

from spar_py import __version__
from spar_py.app.gcpause import resume_collections
from spar_py.app.guard import RunGuard
from spar_py.core.errors import InternalError, KBError, PlanningTimeout, PrologError, SparError, SparValueError
from spar_py.planning.engine import Engine, engine, start_engine
from spar_py.planning.qlf import cache_dir
from spar_py.world.motion import PLANNERS, MotionOptions

EXIT_OK, EXIT_FAIL, EXIT_INPUT, EXIT_INTERNAL, EXIT_TIMEOUT = 0, 1, 2, 3, 4
DEFAULT_PROBLEM = "kb/problems/peg_in_block.yaml"

BANNER = """\
spar-py {version} - SPAR's planner in SWI-Prolog {swi}; loaded: {loaded}.
Try:
    ?- plan({problem}, P).
    ?- phase1({problem}, [trace(true)], plan(P)).
    ?- load_problem('kb/problems/two_pegs.yaml', Q), plan(Q, P).
    ?- loaded_problems(L).
    ?- help(plan/2).
Quit with end_of_file (Ctrl-D)."""


def _err(msg: str) -> None:
    print(f"spar: {msg}", file=sys.stderr)


# ---------------------------------------------------------------------- kb check


def cmd_kb_check(args: argparse.Namespace) -> int:
    """Validate knowledge-base files; one line per file."""
    from spar_py.kb import check_file, iter_kb_files  # kb imports numpy: not at the top (see cmd_plan)

    files = iter_kb_files(args.files)
    if not files:
        _err("kb check: no files given")
        return EXIT_INPUT
    status = EXIT_OK
    for f in files:
        try:
            print(check_file(f, _max_input_bytes(args)))
        except KBError as e:
            _err(str(e))
            status = EXIT_INPUT
    return status


def cmd_kb_derive(args: argparse.Namespace) -> int:
    """Write an object model with every face, stable pose and grasp explicit (derived ones
    too), or a product file with its derived features, mates, seats and order."""
    from spar_py.kb import derive_text  # kb imports numpy: not at the top (see cmd_plan)

    if args.output is not None:
        _check_output_file("-o", Path(args.output))  # before the work, as spar plan does
    pictures = [(opt, Path(f)) for opt, f in (("--dot", args.dot), ("--png", args.png)) if f is not None]
    for opt, f in pictures:
        _check_output_file(opt, f)
    out_dir = Path(args.output).parent if args.output is not None else Path(args.model).parent
    from spar_py.kb.products import derive_product_text, is_product_file

    texts: list[tuple[Path, str]] = []  # (file, text), written all or none after the work
    png = None  # (staged, final)
    if is_product_file(args.model, _max_input_bytes(args)):
        text = derive_product_text(args.model, _max_input_bytes(args), out_dir)
        if pictures:
            dot = _precedence_dot(args, pictures[0][0])
            files = dict(pictures)
            if "--dot" in files:
                texts.append((files["--dot"], dot))
            if "--png" in files:
                from spar_py.pictures.graphs import render_png

                final = files["--png"]
                png = (render_png(dot, args.guard.staging(final) / final.name), final)
    else:
        if pictures:
            raise SparError(f"{args.model}: {pictures[0][0]}: expected a product file (the precedence graph "
                            "is a product's), not an object model")
        text = derive_text(args.model, _max_input_bytes(args), args.robot, out_dir)
    if args.output is not None:
        texts.insert(0, (Path(args.output), text))
    try:
        args.guard.write_all(texts)  # whole or not at all, even on Ctrl-C
    except OSError as e:
        _err(f"{', '.join(str(f) for f, _ in texts)}: cannot write ({e.strerror or e})")
        return EXIT_INPUT
    if png is not None:
        with args.guard.commit():
            os.replace(*png)
    if args.output is None:
        sys.stdout.write(text)
    return EXIT_OK


def _precedence_dot(args: argparse.Namespace, option: str) -> str:
    """``spar kb derive --dot/--png``: the product's derived precedence graph as DOT text
    (pictures.precedence), its derivation read again from the cache by content."""
    from spar_py.kb.products import load_product_derived
    from spar_py.kb.reader import parse_yaml
    from spar_py.pictures.precedence import precedence_dot

    data = parse_yaml(Path(args.model), _max_input_bytes(args))
    unit = str((data.get("units") or {}).get("length") or "mm")
    lp = load_product_derived(args.model, unit, _max_input_bytes(args))
    if lp.derived is None:
        raise SparError(f"{args.model}: {option}: expected a product with mesh: parts (its precedence derived), "
                        "not one whose parts all give model:")
    return precedence_dot(lp.derived, lp.product.name)


# ---------------------------------------------------------------------- repl


def cmd_repl(args: argparse.Namespace) -> int:
    """The Prolog toplevel with the planner and a problem loaded. Interactive on a terminal;
    with standard input piped, a scripted session (spar_toplevel:batch_toplevel/0: each
    query answered once, so none is swallowed as the answer to "more?")."""
    from spar_py.kb import load_problem  # kb imports numpy: not at the top (see cmd_plan)

    cell = load_problem(args.problem)
    eng = engine()
    eng.query_once("spar_toplevel:collect_docs")  # before loading: it reloads kb.pl
    eng.load_cell(cell)
    swi = eng.query_once("current_prolog_flag(version, V)")["V"]
    loaded = ", ".join(eng.query_once("spar:loaded_problems(L)")["L"])
    print(BANNER.format(version=__version__, swi=f"{swi // 10000}.{swi // 100 % 100}.{swi % 100}",
                        problem=cell.name, loaded=loaded))
    sys.stdout.flush()
    if sys.stdin.isatty():
        eng.query_once("prolog")
    else:
        eng.query_once("spar_toplevel:batch_toplevel")
    return EXIT_OK


# ---------------------------------------------------------------------- plan


def _existing_parent(path: Path) -> Path:
    """The nearest ancestor of ``path`` that exists."""
    p = path.absolute().parent
    while not p.exists() and p != p.parent:
        p = p.parent
    return p


def _check_output_file(option: str, path: Path) -> None:
    """An output file must be creatable: not a directory, in a writable directory (exit 2)."""
    if path.is_dir():
        raise SparError(f"{path}: {option}: expected a file to write, not a directory")
    parent = _existing_parent(path)
    if not parent.is_dir():
        raise SparError(f"{path}: {option}: expected a path in a directory, not under the file {parent}")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise SparError(f"{path}: {option}: expected a writable directory, not {parent} (permission denied)")


def _check_output_dir(option: str, path: Path, what: str = "the pictures") -> None:
    """An output directory (for ``what``) must be a directory (or creatable) in a writable place (exit 2)."""
    if path.exists() and not path.is_dir():
        raise SparError(f"{path}: {option}: expected a directory for {what}, not a file")
    target = path if path.is_dir() else _existing_parent(path)
    if not target.is_dir():
        raise SparError(f"{path}: {option}: expected a path in a directory, not under the file {target}")
    parent = _existing_parent(path)
    for d in {target, parent}:
        if not os.access(d, os.W_OK | os.X_OK):
            raise SparError(f"{path}: {option}: expected a writable directory, not {d} (permission denied)")


def cmd_plan(args: argparse.Namespace) -> int:
    """Plan a problem; print the plan (or its JSON) and write pictures if asked.

    Every output is checked before planning (exit 2 if one cannot be written), made in a
    staging directory beside it (RunGuard.staging), and moved into place at the end under
    the run guard, so a timeout, Ctrl-C or SIGTERM never leaves part of them, nor any
    temporary. After the commit the run is done: a late signal changes nothing."""
    output = Path(args.output) if args.output else None
    picture_dirs = sorted({Path(d) for d in (args.dot, args.png) if d})
    animate = Path(args.animate) if args.animate else None
    html = Path(args.html) if args.html else None
    if output is not None:
        _check_output_file("-o", output)
    if html is not None:
        _check_output_file("--html", html)
    if animate is not None:
        if args.no_motion or args.phase1_only:
            raise SparValueError("--animate replays the plan's motions: not with --no-motion or --phase1-only")
        if animate.suffix.lower() != ".gif":
            raise SparValueError(f"--animate {animate}: expected a .gif file name")
        _check_output_file("--animate", animate)
    for d in picture_dirs:
        _check_output_dir("--png" if args.png and Path(args.png) == d else "--dot", d)
    guard = args.guard
    start_engine()  # Prolog loads the planner while the imports below run
    from spar_py.kb import load_problem
    from spar_py.planning.messages import expected_failures
    from spar_py.planning.planner import Outcome, Planner, dumps

    cell = load_problem(args.problem, max_bytes=_max_input_bytes(args))
    resume_collections()  # the planning run allocates (and frees) as it goes
    planner = Planner(max_actions=args.max_actions, max_instances=args.max_instances,
                      separation=False if args.no_separation else None,
                      paper_placements=args.paper_placements,
                      motion=False if args.no_motion else (True if args.motion or args.animate else None),
                      motion_options=_motion_options(args))
    plan = planner.plan(cell, phase1_only=args.phase1_only, trace=args.trace)
    if plan.outcome is Outcome.TIMEOUT:
        raise PlanningTimeout(f"{cell.name}: no result within {args.timeout:g} s")
    failing = expected_failures(plan.instance) if plan.ok else None  # the text plan's first line
    staged: list[tuple[Path, Path]] = []  # (temporary, final)
    for d in picture_dirs:
        from spar_py.pictures import write_pictures  # matplotlib: only with --png/--dot

        for p in write_pictures(cell, plan, guard.staging(d)):
            staged.append((p, d / p.name))
    if animate is not None:
        from spar_py.pictures.animate import write_animation  # matplotlib: only with --animate

        tmpgif = guard.staging(animate) / animate.name
        write_animation(cell, plan, tmpgif)
        staged.append((tmpgif, animate))
    page = None
    if html is not None and plan.ok:
        from spar_py.pictures.viewer import write_viewer  # the mesh layer: only with --html

        page = write_viewer(cell, plan, guard.staging(html) / html.name)
        staged.append((page.path, html))
    if output is not None:
        tmpfile = guard.staging(output) / output.name
        doc = plan.to_json()
        if "problem_file" not in doc:  # where `spar view` finds the cell again
            doc = {**doc, "problem_file": str(Path(args.problem).resolve())}
        tmpfile.write_text(dumps(doc) + "\n", encoding="utf-8")
        staged.append((tmpfile, output))
    with guard.commit():
        for d in picture_dirs:
            d.mkdir(parents=True, exist_ok=True)
        for tmp, final in staged:
            os.replace(tmp, final)
    if args.json and output is None:
        sys.stdout.write(plan.dumps() + "\n")
    elif not args.json:  # JSON carries the colliding pairs in reason.collisions, the last line in reason.summary
        why = plan.explanation if plan.outcome is Outcome.NO_PLAN else None
        for line in why.collisions if why is not None else ():
            print(line)
        if failing:
            print(failing)
        sys.stdout.write(plan.trace)
        if why is not None and why.summary:
            print(why.summary)
    for d in picture_dirs:
        n = sum(1 for _, f in staged if f.parent == d)
        print(f"spar: wrote {n} pictures to {d}", file=sys.stderr)
    if animate is not None:
        print(f"spar: wrote the animation to {animate}", file=sys.stderr)
    if html is not None:
        print(f"spar: wrote the viewer to {html} ({page.steps} steps, {page.parts} parts)" if page is not None
              else f"spar: no plan: no viewer written to {html}", file=sys.stderr)
    if failing and args.strict:
        print(f"spar: --strict: a plan with expected failures (error count {plan.error_count})", file=sys.stderr)
        return EXIT_FAIL
    return EXIT_OK if plan.ok else EXIT_FAIL


# ---------------------------------------------------------------------- view


def _read_plan_json(path: Path, max_bytes: int) -> dict:
    """The plan document of ``spar plan -o``'s file ``path``; SparError (one line, exit 2) naming the
    file and what was expected if it is missing, too large, not JSON or not a plan."""
    try:
        size = path.stat().st_size
        if path.is_dir():
            raise SparError(f"{path}: expected a plan JSON file (spar plan -o), not a directory")
        if size > max_bytes:
            raise SparError(f"{path}: expected a plan JSON of at most {max_bytes} bytes (--max-input-bytes), "
                            f"not {size}")
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise SparError(f"{path}: no such file (expected a plan JSON written by spar plan -o)") from None
    except (OSError, UnicodeDecodeError) as e:
        raise SparError(f"{path}: cannot read a plan JSON ({getattr(e, 'strerror', None) or e})") from None
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as e:
        raise SparError(f"{path}: expected a plan JSON (spar plan -o), not JSON: {e.msg} at line {e.lineno}") from None
    if not isinstance(doc, dict) or "outcome" not in doc or "schema" not in doc:
        found = f"an object with keys {', '.join(list(doc)[:5])}" if isinstance(doc, dict) else type(doc).__name__
        raise SparError(f"{path}: expected a plan JSON written by spar plan -o (keys schema, outcome, instance), "
                        f"found {found or 'an empty object'}")
    if doc.get("outcome") != "plan":
        raise SparError(f"{path}: expected a plan to view, but its outcome is {doc.get('outcome')!r}: no steps to show")
    return doc


def _plan_problem(path: Path, doc: dict, given: str | None) -> Path:
    """The problem file of a plan JSON: ``--problem``, else the file's ``problem_file`` (spar plan -o
    writes it), else kb/problems/<problem>.yaml; SparError if none is there."""
    if given is not None:
        return Path(given)
    tried = []
    if doc.get("problem_file"):
        p = Path(str(doc["problem_file"]))
        tried.append(p if p.is_absolute() else path.parent / p)
    if doc.get("problem"):
        tried.append(Path("kb/problems") / f"{doc['problem']}.yaml")
    for p in tried:
        if p.is_file():
            return p
    raise SparError(f"{path}: cannot find the problem file of plan {doc.get('problem')!r} (tried "
                    f"{', '.join(map(str, tried)) or 'nothing'}): give it with --problem FILE")


def cmd_view(args: argparse.Namespace) -> int:
    """Write the 3-D viewer page of a plan JSON (``spar view PLAN.json [-o FILE]``): one HTML file that
    opens offline. The output is checked before any work and written whole or not at all."""
    src = Path(args.plan)
    out = Path(args.output) if args.output else src.with_suffix(".html")
    if out.resolve() == src.resolve():
        raise SparError(f"{out}: -o: expected an HTML file other than the plan JSON itself")
    _check_output_file("-o", out)
    max_bytes = _max_input_bytes(args)
    doc = _read_plan_json(src, VIEW_MAX_PLAN_BYTES if args.max_input_bytes is None else max_bytes)
    problem = _plan_problem(src, doc, args.problem)
    # kb (numpy) and the viewer (the mesh layer): this command only, not every command's start-up
    from spar_py.kb import load_problem
    from spar_py.pictures.viewer import write_viewer
    from spar_py.planning.planner import Plan

    cell = load_problem(problem, max_bytes=max_bytes)
    if cell.name != doc.get("problem"):
        raise SparError(f"{problem}: expected the problem {doc.get('problem')!r} of {src}, not {cell.name!r}")
    try:
        page = write_viewer(cell, Plan.from_json(doc), args.guard.staging(out) / out.name)
        with args.guard.commit():
            os.replace(page.path, out)
    except OSError as e:
        raise SparError(f"{out}: -o: cannot write the page ({e.strerror or e})") from None
    print(f"spar: wrote the viewer to {out} ({page.steps} steps, {page.parts} parts)", file=sys.stderr)
    return EXIT_OK


#: The largest plan JSON `spar view` reads (bytes): a plan with motions holds every waypoint.
VIEW_MAX_PLAN_BYTES = 200_000_000


# ---------------------------------------------------------------------- regress


def cmd_regress(args: argparse.Namespace) -> int:
    """Check every problem under a directory against its expected outcome."""
    from spar_py.app.regress import run_regression  # dask.distributed for --scheduler: this command only

    if args.scheduler is not None and args.jobs != 1:
        raise SparError("regress: -j N runs processes on this machine, --scheduler on a cluster: give one")
    return run_regression(Path(args.dir), jobs=args.jobs, update=args.update, scheduler=args.scheduler,
                          write_all=args.guard.write_all)


# ---------------------------------------------------------------------- gen


def cmd_gen(args: argparse.Namespace) -> int:
    """Generate a problem (``spar gen assembly --parts N``, ``spar gen board N``)."""
    from spar_py.app.gen import generate_assembly, generate_board  # the collision layer: this command only

    if args.gen_command == "layout":
        return _gen_layout(args)
    out = Path(args.output)
    _check_output_dir("-o", out, "the generated problem")
    stage = args.guard.staging(out)  # beside it: the whole tree, or nothing, even on Ctrl-C
    if args.gen_command == "board":
        path = generate_board(args.n, stage, rows=args.rows)
    else:
        path = generate_assembly(args.parts, stage, blocks=args.blocks)
    args.guard.move_tree(stage, out)
    print(out / path.relative_to(stage))
    return EXIT_OK


def _gen_layout(args: argparse.Namespace) -> int:
    """``spar gen layout PRODUCT.yaml [--robot R] [-o PROBLEM.yaml]``: the problem of the
    product's parts laid out for the robot, to the file or standard output."""
    from spar_py.app.gen import layout_problem_text

    out = Path(args.output) if args.output else Path(args.product).with_name(f"{Path(args.product).stem}_layout.yaml")
    if args.output:
        _check_output_file("-o", out)
    text = layout_problem_text(args.product, args.robot, out)
    if args.output:
        args.guard.write_text(out, text)  # atomically, even on Ctrl-C
        print(out)
    else:
        sys.stdout.write(text)
    return EXIT_OK


# ---------------------------------------------------------------------- main

def cmd_cache(args: argparse.Namespace) -> int:
    """Compile the planner's Prolog into the cache now, with its saved state (``spar cache``; set-up
    runs it): one line on stderr says where the image is, or that the cache is off."""
    from spar_py.phase2 import instance  # noqa: F401 - the plan command's dataclasses, compiled into
    from spar_py.planning import planner  # noqa: F401 - the methods image (startup.dcimage) at exit

    eng = Engine()
    base = cache_dir()
    where = "the cache is off" if base is None else f"cache {base}"
    state = CACHE_STATES.get(eng.state_status, "")
    print(f"setup: planner Prolog {CACHE_LOADS.get(eng.loaded_from, eng.loaded_from)}{state} ({where})",
          file=sys.stderr)
    return EXIT_OK


#: ``spar cache``'s words for how the engine loaded the planner and for its saved state.
CACHE_LOADS = {"qlf": "image up to date", "compiled": "compiled to a .qlf image", "source": "consulted from source",
               "state": "image up to date"}
CACHE_STATES = {"written": ", saved state written", "used": ", saved state up to date",
                "ready": ", saved state up to date", "busy": ", saved state being written by another process",
                "refused": ", saved state refused (SWI-Prolog did not start from it)",
                "unwritable": ", saved state not written (the cache is not writable)"}


COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {
    "cache": cmd_cache,
    "kb_check": cmd_kb_check,
    "kb_derive": cmd_kb_derive,
    "repl": cmd_repl,
    "plan": cmd_plan,
    "view": cmd_view,
    "regress": cmd_regress,
    "gen": cmd_gen,
}


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``spar``."""
    p = argparse.ArgumentParser(prog="spar", description="SPAR assembly task planner (Hutchinson & Kak)",
                                epilog=EXIT_CODES, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--version", action="version", version=f"spar-py {__version__}")
    sub = p.add_subparsers(dest="command", required=True)

    kb = sub.add_parser("kb", help="knowledge-base tools")
    kbsub = kb.add_subparsers(dest="kb_command", required=True)
    check = kbsub.add_parser("check", help="validate KB files (problems, objects, robots) or directories")
    check.add_argument("files", nargs="+")
    _add_max_input_bytes(check)
    check.set_defaults(func="kb_check")
    derive = kbsub.add_parser("derive", help="write an object model with its derived faces, stable poses and "
                              "grasps explicit (to review and diff)")
    derive.add_argument("model", help="an object model file, e.g. kb/objects/peg_shape.yaml, or a product file "
                        "(its mesh parts' features, mates and order derived)")
    derive.add_argument("-o", "--output", help="write the model to this file (atomically) instead of stdout")
    derive.add_argument("--dot", metavar="OUT.dot", help="a product file: also write its derived precedence graph "
                        "(insertions with their directions, precedence with its reasons) as Graphviz DOT text")
    derive.add_argument("--png", metavar="OUT.png", help="a product file: also draw that graph with Graphviz's dot")
    derive.add_argument("--robot", help="derive grasps for this robot's gripper (default: a 101.6 mm opening, "
                        "the PUMA 762's)")
    _add_max_input_bytes(derive)
    derive.set_defaults(func="kb_derive")

    repl = sub.add_parser("repl", help="interactive Prolog toplevel with the planner loaded")
    repl.add_argument("problem", nargs="?", default=DEFAULT_PROBLEM)
    repl.set_defaults(func="repl")

    plan = sub.add_parser("plan", help="plan a problem (phase 1 and phase 2)")
    plan.add_argument("problem", help="a problem file, e.g. kb/problems/peg_in_block.yaml")
    plan.add_argument("--json", action="store_true", help="print the plan as JSON (schema 3)")
    plan.add_argument("-o", "--output", help="write the JSON to this file (atomically)")
    plan.add_argument("--trace", action="store_true", help="print the goal stacks at each step (Figs. 21-22) "
                      "and, without a plan, the Prolog goal that could not be met")
    plan.add_argument("--strict", action="store_true",
                      help="exit 1 on a plan with expected failures (error count > 0: actions verified and "
                           "recovered because their uncertainty-reduction preconditions do not hold)")
    plan.add_argument("--phase1-only", action="store_true", help="stop after the partial plan")
    plan.add_argument("--max-actions", type=_positive_int, metavar="N",
                      help="bound on the plan size (default: derived from the problem, twice its "
                           "lower bound on the plan size and at least 12; prolog/spar_defaults.pl)")
    plan.add_argument("--max-instances", type=_positive_int, metavar="N",
                      help="plan instances examined at most in phase 2 (default: prolog/spar_defaults.pl)")
    plan.add_argument("--no-separation", action="store_true",
                      help="declobber without separation, as the paper's planner")
    plan.add_argument("--paper-placements", action="store_true",
                      help="assume a put-down into a stable pose is reachable somewhere (the paper's rule)")
    plan.add_argument("--timeout", type=_positive_float, metavar="S", help="give up after S seconds")
    _add_max_input_bytes(plan)
    plan.add_argument("--motion", action="store_true",
                      help="plan the joint paths between the end-points (default: as the problem's motion: key)")
    plan.add_argument("--no-motion", action="store_true",
                      help="plan the end-points only (the paper's phase 2), no joint paths between them")
    plan.add_argument("--animate", metavar="FILE.gif", help="write an animation of the plan's motions")
    plan.add_argument("--motion-planner", choices=sorted(PLANNERS), default="rrtconnect",
                      help="OMPL planner for the free motions (default rrtconnect)")
    plan.add_argument("--motion-budget", type=_positive_float, default=1.0, metavar="S",
                      help="OMPL seconds per free motion (default 1)")
    plan.add_argument("--motion-seed", type=int, default=0, metavar="N", help="OMPL's random seed (default 0)")
    plan.add_argument("--approach-length", type=_positive_length, metavar="L",
                      help="approach and retreat length in the problem's length unit (default 2 in)")
    plan.add_argument("--dot", metavar="DIR", help="write the ordering graph, network and cell pictures here")
    plan.add_argument("--png", metavar="DIR", help="same as --dot (both write .dot and .png)")
    plan.add_argument("--html", metavar="FILE", help="write the plan's 3-D viewer: one HTML page that opens offline")
    plan.set_defaults(func="plan")

    view = sub.add_parser("view", help="write the 3-D viewer of a plan JSON (spar plan -o): one HTML page")
    view.add_argument("plan", metavar="PLAN.json", help="a plan written by spar plan -o")
    view.add_argument("-o", "--output", metavar="FILE", help="the page to write (default: PLAN.html beside it)")
    view.add_argument("--problem", metavar="FILE", help="the plan's problem file (default: the one the plan "
                      "JSON names, else kb/problems/<problem>.yaml)")
    _add_max_input_bytes(view)
    view.set_defaults(func="view")

    reg = sub.add_parser("regress", help="check every problem under DIR against its expected outcome")
    reg.add_argument("dir", nargs="?", default="kb/problems")
    reg.add_argument("-j", "--jobs", type=_positive_int, default=1, help="worker processes on this machine")
    reg.add_argument("--scheduler", metavar="ADDRESS",
                     help="run each problem as a task on this Dask scheduler (tcp://host:8786; "
                          "needs the 'cluster' extra)")
    reg.add_argument("--update", action="store_true", help="accept the new outcomes as expected")
    reg.set_defaults(func="regress")

    gen = sub.add_parser("gen", help="generate problems")
    gensub = gen.add_subparsers(dest="gen_command", required=True)
    asm = gensub.add_parser("assembly", help="N pegs into N blocks (N <= 100)")
    asm.add_argument("--parts", type=_positive_int, required=True, metavar="N")
    asm.add_argument("--blocks", choices=("hole-down", "on-side", "hole-up", "hole-up-small"), default=None,
                     help="how the blocks start: hole-down (each turned over, 4 actions a pair, N <= 42), "
                          "on-side (each turned a quarter turn, 4 actions a pair, N <= 70), "
                          "hole-up (2 actions a pair, N <= 72), hole-up-small (half-size parts, N <= 100); "
                          "default: the first that holds N")
    asm.add_argument("-o", "--output", default="out/gen", metavar="DIR")
    asm.set_defaults(func="gen")
    board = gensub.add_parser("board", help="a task board: N pins into N holes of one board")
    board.add_argument("n", type=_positive_int, metavar="N", help="insertions (holes and pins)")
    board.add_argument("--rows", type=_positive_int, default=None, metavar="R",
                       help="the board's rows of holes (default about 0.9 sqrt(N)); columns ceil(N / R)")
    board.add_argument("-o", "--output", default="out/gen", metavar="DIR")
    board.set_defaults(func="gen")
    lay = gensub.add_parser("layout", help="a product's parts laid out on the table for a robot (a problem)")
    lay.add_argument("product", metavar="PRODUCT.yaml")
    lay.add_argument("--robot", default=str(Path(__file__).resolve().parents[3] / "kb" / "robots" / "ur5e.yaml"),
                     metavar="R", help="the robot file (default kb/robots/ur5e.yaml)")
    lay.add_argument("-o", "--output", default=None, metavar="PROBLEM.yaml",
                     help="write the problem here (default: standard output, paths relative to the product's folder)")
    lay.set_defaults(func="gen")

    cache = sub.add_parser("cache", help="compile the planner's Prolog into its cache now (set-up runs it)")
    cache.set_defaults(func="cache")
    return p


def _motion_options(args: argparse.Namespace) -> MotionOptions:
    """The plan command's motion options (the approach length in the problem's unit)."""
    return MotionOptions(planner=args.motion_planner, time_budget_s=args.motion_budget, seed=args.motion_seed,
                         approach_length=args.approach_length)


def _add_max_input_bytes(p: argparse.ArgumentParser) -> None:
    # the default is kb.MAX_INPUT_BYTES (a test checks this text); not imported here: kb
    # imports numpy, and `spar plan` starts Prolog before it
    p.add_argument("--max-input-bytes", type=_positive_int, metavar="N",
                   help="refuse a KB file larger than N bytes (default 1000000)")


def _max_input_bytes(args: argparse.Namespace) -> int:
    """The per-file size limit of a command: --max-input-bytes, or kb.MAX_INPUT_BYTES."""
    from spar_py.kb import MAX_INPUT_BYTES  # kb imports numpy: not at the top (see cmd_plan)

    return MAX_INPUT_BYTES if args.max_input_bytes is None else int(args.max_input_bytes)


def _positive_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, not {text!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, not {v}")
    return v


def _positive(what: str):
    """An argparse type: a positive finite number, the message naming ``what`` it measures."""
    def parse(text: str) -> float:
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number of {what}, not {text!r}") from None
        if not v > 0 or v != v:
            raise argparse.ArgumentTypeError(f"expected a positive number of {what}, not {text}")
        return v
    return parse


_positive_float = _positive("seconds")
_positive_length = _positive("the cell's length unit")


EXIT_CODES = """\
exit codes:
  0    a plan (or every check passed)
  1    no plan, or with --strict a plan with expected failures (or a check or
       regression failed)
  2    bad input or arguments: a knowledge-base file, an option, an output that
       cannot be written
  3    internal error: a bug in spar-py (one line; please report it)
  4    timeout (--timeout)
  130  interrupted (Ctrl-C); 143 terminated (SIGTERM)"""


def main(argv: list[str] | None = None) -> None:
    """Entry point of the ``spar`` console script: one line on stderr for every error,
    never a traceback; the exit codes of EXIT_CODES."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.func != "plan":  # `spar plan` resumes them once its problem is read
        resume_collections()
    try:
        # the guard alone enforces --timeout: Prolog's own time limit, landing inside a
        # foreign predicate, can make SWI-Prolog print a second line on stderr
        with RunGuard(getattr(args, "timeout", None), grace=0.0) as args.guard:
            code = COMMANDS[args.func](args)
    except KBError as e:
        _err(str(e))
        code = EXIT_INPUT
    except PlanningTimeout as e:
        _err(f"timeout: {e}")
        code = EXIT_TIMEOUT
    except (PrologError, InternalError) as e:
        _err(f"internal error (please report it): {e}")
        code = EXIT_INTERNAL
    except SparError as e:
        _err(str(e))
        code = EXIT_INPUT
    except KeyboardInterrupt:
        _err("interrupted")
        code = 130
    except OSError as e:
        _err(f"{e.filename or ''}: {e.strerror or e}".lstrip(": "))
        code = EXIT_INPUT
    except Exception as e:  # a bug: one line, never a traceback
        _err(f"internal error (please report it): {type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''}")
        code = EXIT_INTERNAL
    sys.exit(code)


#: Libraries whose bindings (nanobind) report, at interpreter shutdown, every object of theirs
#: still alive as a leak on stderr: with one of them loaded, :func:`exiting` leaves the heap to
#: the interpreter's usual shutdown collections (which free those objects).
LEAK_REPORTING = ("ompl", "manifold3d")


def exiting(code: object = ...) -> None:
    """The process ends next (the console script's last call),
    with the SystemExit ``code`` that :func:`main` raised (``...``: it raised none). Move every
    object to the collector's permanent generation (gc.freeze), so the interpreter's shutdown
    collections skip the heap numpy, casadi, the embedded Prolog's bridge and the plan left
    (in a cold ``spar plan``, more than the run's own output); then, for a run
    that ended with a plan or without one (codes 0 and 1), :func:`_end_now`. Every output file
    is closed and in place before :func:`main` exits. Neither when a LEAK_REPORTING library is
    loaded (a plan with motions: OMPL): the usual shutdown then runs."""
    if any(name in sys.modules for name in LEAK_REPORTING):
        return
    gc.freeze()
    if code is None or (isinstance(code, int) and code in (EXIT_OK, EXIT_FAIL)):
        _end_now(int(code or 0))


def _end_now(code: int) -> None:
    """End the process with ``code`` at once (os._exit), skipping the interpreter's teardown,
    which frees every module and object one by one, once
    what that shutdown would still do for this run is done: Python's stdout and stderr and
    SWI-Prolog's user_output and user_error flushed. Returns (the usual shutdown follows) if a
    flush fails (a closed pipe: the usual path reports it), if a thread other than a
    daemon is still running (the usual shutdown waits for it), or if anything is registered
    with atexit (or the interpreter cannot say: not CPython)."""
    registered = getattr(atexit, "_ncallbacks", None)
    if registered is None or registered() or any(
            t is not threading.main_thread() and not t.daemon and t.is_alive() for t in threading.enumerate()):
        return
    try:
        janus = sys.modules.get("janus_swi")
        if janus is not None and hasattr(janus, "query_once"):
            janus.query_once("flush_output(user_output), flush_output(user_error)")
        sys.stdout.flush()
        sys.stderr.flush()
    except Exception:  # noqa: BLE001 - the usual shutdown then says what it says
        return
    os._exit(code)
