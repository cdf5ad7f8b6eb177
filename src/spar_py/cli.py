"""The ``spar`` command.

Exit codes: 0 success; 1 a plan could not be found or a check failed; 2 bad input
(a knowledge-base file, an argument); 3 an internal Prolog error. Errors are one
line on stderr, never a traceback.
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path
from typing import Callable

from . import __version__
from .errors import KBError, PlanningTimeout, PrologError, SparError

EXIT_OK, EXIT_FAIL, EXIT_INPUT, EXIT_INTERNAL, EXIT_TIMEOUT = 0, 1, 2, 3, 4
DEFAULT_PROBLEM = "kb/problems/peg_in_block.yaml"

BANNER = """\
spar-py {version} - SPAR's planner in SWI-Prolog {swi}; problem {problem} loaded.
Try:
    ?- plan({problem}, P), print_plan(P).
    ?- phase1({problem}, [trace(true)], plan(P)), print_partial(P).
    ?- kb:grasp(peg, G, gfaces(F), _, _, _).
Quit with end_of_file (Ctrl-D)."""


def _err(msg: str) -> None:
    print(f"spar: {msg}", file=sys.stderr)


# ---------------------------------------------------------------------- kb check


def cmd_kb_check(args: argparse.Namespace) -> int:
    """Validate knowledge-base files; one line per file."""
    from .kb import check_file, iter_kb_files

    files = iter_kb_files(args.files)
    if not files:
        _err("kb check: no files given")
        return EXIT_INPUT
    status = EXIT_OK
    for f in files:
        try:
            print(check_file(f))
        except KBError as e:
            _err(str(e))
            status = EXIT_INPUT
    return status


# ---------------------------------------------------------------------- repl


def cmd_repl(args: argparse.Namespace) -> int:
    """The interactive Prolog toplevel with planner and a problem loaded."""
    from .engine import engine
    from .kb import load_problem

    cell = load_problem(args.problem)
    eng = engine()
    eng.load_cell(cell)
    swi = eng.query_once("current_prolog_flag(version, V)")["V"]
    print(BANNER.format(version=__version__, swi=f"{swi // 10000}.{swi // 100 % 100}.{swi % 100}", problem=cell.name))
    sys.stdout.flush()
    eng.query_once("prolog")
    return EXIT_OK


# ---------------------------------------------------------------------- plan


def write_atomically(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary file and a rename: never half a file."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as f:
            f.write(text)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def cmd_plan(args: argparse.Namespace) -> int:
    """Plan a problem; print the plan (or its JSON) and write pictures if asked."""
    from .engine import start_engine

    start_engine()  # Prolog consults the planner while the imports below run
    from .planner import Planner

    planner = Planner(max_actions=args.max_actions, max_instances=args.max_instances,
                      separation=not args.no_separation, timeout=args.timeout,
                      paper_placements=args.paper_placements)
    cell = planner.load_problem(args.problem)
    plan = planner.plan(cell, phase1_only=args.phase1_only, trace=args.trace)
    if args.json:
        text = plan.dumps() + "\n"
        if args.output:
            write_atomically(Path(args.output), text)
        else:
            sys.stdout.write(text)
    else:
        sys.stdout.write(plan.trace)
        if args.output:
            write_atomically(Path(args.output), plan.dumps() + "\n")
    for outdir in {d for d in (args.dot, args.png) if d}:
        from .pictures import write_pictures

        paths = write_pictures(cell, plan.to_json(), Path(outdir))
        print(f"spar: wrote {len(paths)} pictures to {outdir}", file=sys.stderr)
    return EXIT_OK if plan.ok else EXIT_FAIL


# ---------------------------------------------------------------------- regress


def cmd_regress(args: argparse.Namespace) -> int:
    """Check every problem under a directory against its expected outcome."""
    from .regress import run_regression

    return run_regression(Path(args.dir), jobs=args.jobs, update=args.update)


# ---------------------------------------------------------------------- gen


def cmd_gen(args: argparse.Namespace) -> int:
    """Generate a problem (``spar gen assembly --parts N``)."""
    from .gen import generate_assembly

    path = generate_assembly(args.parts, Path(args.output))
    print(path)
    return EXIT_OK


# ---------------------------------------------------------------------- main

COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {
    "kb_check": cmd_kb_check,
    "repl": cmd_repl,
    "plan": cmd_plan,
    "regress": cmd_regress,
    "gen": cmd_gen,
}


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``spar``."""
    p = argparse.ArgumentParser(prog="spar", description="SPAR assembly task planner (Hutchinson & Kak)")
    p.add_argument("--version", action="version", version=f"spar-py {__version__}")
    sub = p.add_subparsers(dest="command", required=True)

    kb = sub.add_parser("kb", help="knowledge-base tools")
    kbsub = kb.add_subparsers(dest="kb_command", required=True)
    check = kbsub.add_parser("check", help="validate KB files (problems, objects, robots) or directories")
    check.add_argument("files", nargs="+")
    check.set_defaults(func="kb_check")

    repl = sub.add_parser("repl", help="interactive Prolog toplevel with the planner loaded")
    repl.add_argument("problem", nargs="?", default=DEFAULT_PROBLEM)
    repl.set_defaults(func="repl")

    plan = sub.add_parser("plan", help="plan a problem (phase 1 and phase 2)")
    plan.add_argument("problem", help="a problem file, e.g. kb/problems/peg_in_block.yaml")
    plan.add_argument("--json", action="store_true", help="print the plan as JSON (schema 1)")
    plan.add_argument("-o", "--output", help="write the JSON to this file (atomically)")
    plan.add_argument("--trace", action="store_true", help="print the goal stacks at each step (Figs. 21-22)")
    plan.add_argument("--phase1-only", action="store_true", help="stop after the partial plan")
    plan.add_argument("--max-actions", type=_positive_int, default=12, metavar="N",
                      help="bound on the plan size (default 12)")
    plan.add_argument("--max-instances", type=_positive_int, default=50, metavar="N",
                      help="plan instances examined at most in phase 2 (default 50)")
    plan.add_argument("--no-separation", action="store_true",
                      help="declobber without separation, as the paper's planner")
    plan.add_argument("--paper-placements", action="store_true",
                      help="assume a put-down into a stable pose is reachable somewhere (the paper's rule)")
    plan.add_argument("--timeout", type=_positive_float, metavar="S", help="give up after S seconds")
    plan.add_argument("--dot", metavar="DIR", help="write the ordering graph, network and cell pictures here")
    plan.add_argument("--png", metavar="DIR", help="same as --dot (both write .dot and .png)")
    plan.set_defaults(func="plan")

    reg = sub.add_parser("regress", help="check every problem under DIR against its expected outcome")
    reg.add_argument("dir", nargs="?", default="kb/problems")
    reg.add_argument("-j", "--jobs", type=_positive_int, default=1, help="worker processes")
    reg.add_argument("--update", action="store_true", help="accept the new outcomes as expected")
    reg.set_defaults(func="regress")

    gen = sub.add_parser("gen", help="generate problems")
    gensub = gen.add_subparsers(dest="gen_command", required=True)
    asm = gensub.add_parser("assembly", help="N pegs into N blocks, each block to be turned over")
    asm.add_argument("--parts", type=_positive_int, required=True, metavar="N")
    asm.add_argument("-o", "--output", default="out/gen", metavar="DIR")
    asm.set_defaults(func="gen")
    return p


def _positive_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, not {text!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, not {v}")
    return v


def _positive_float(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of seconds, not {text!r}") from None
    if not v > 0 or v != v:
        raise argparse.ArgumentTypeError(f"expected a positive number of seconds, not {text}")
    return v


def main(argv: list[str] | None = None) -> None:
    """Entry point of the ``spar`` console script."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        code = COMMANDS[args.func](args)
    except KBError as e:
        _err(str(e))
        code = EXIT_INPUT
    except PlanningTimeout as e:
        _err(f"timeout: {e}")
        code = EXIT_TIMEOUT
    except PrologError as e:
        _err(f"prolog: {e.message.splitlines()[0] if e.message else e.term}")
        code = EXIT_INTERNAL
    except SparError as e:
        _err(str(e))
        code = EXIT_INPUT
    except KeyboardInterrupt:
        code = 130
    sys.exit(code)


if __name__ == "__main__":
    main(sys.argv[1:])

