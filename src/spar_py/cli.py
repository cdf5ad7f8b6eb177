"""The ``spar`` command.

Exit codes: 0 success; 1 a plan could not be found or a check failed; 2 bad input
(a knowledge-base file, an argument); 3 an internal Prolog error. Errors are one
line on stderr, never a traceback.
"""
from __future__ import annotations

import argparse
import sys
from typing import Callable

from . import __version__
from .errors import KBError, PlanningTimeout, PrologError, SparError

EXIT_OK, EXIT_FAIL, EXIT_INPUT, EXIT_INTERNAL = 0, 1, 2, 3
DEFAULT_PROBLEM = "kb/problems/peg_in_block.yaml"

BANNER = """\
spar-py {version} - SPAR's planner in SWI-Prolog {swi}; problem {problem} loaded.
Try:
    ?- plan_phase1({problem}, P), print_partial(P).
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


# ---------------------------------------------------------------------- main

COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {
    "kb_check": cmd_kb_check,
    "repl": cmd_repl,
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
    return p


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
        code = EXIT_FAIL
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

