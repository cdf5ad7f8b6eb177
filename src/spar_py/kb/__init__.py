"""The knowledge base: YAML files -> validated models (core.model) -> Prolog facts.

One idea a module, imported one way (each only from those above it in this list):
node (a value with its file and key path; message quoting), reader (the bounded safe YAML
reader), schema (the schema language, the file kinds), values (units, tm rows, frames),
terms (goals and initial facts as term data), objects, robots (the model loaders),
sanity (is the cell physically possible), problem (a problem file to a Cell),
prolog_facts (a Cell as Prolog facts), check (``spar kb check`` and ``spar kb derive``).
Every malformed input raises a one-line :class:`~spar_py.core.errors.KBError`; the
formats and messages are documented in docs/kb-format.md.
"""
from __future__ import annotations

from spar_py.core.errors import KBError, UnknownKeyError, WrongKindError
from spar_py.kb import sanity
from spar_py.kb.check import check_file, derive_text, iter_kb_files
from spar_py.kb.objects import load_object
from spar_py.kb.problem import load_problem
from spar_py.kb.prolog_facts import facts, position_class
from spar_py.kb.reader import MAX_INPUT_BYTES, SAFE_LOADER, parse_yaml
from spar_py.kb.robots import load_robot
from spar_py.kb.schema import KINDS, file_kind, read_kb, read_yaml
from spar_py.kb.terms import parse_term, term_text

__all__ = [
    "KINDS",
    "MAX_INPUT_BYTES",
    "SAFE_LOADER",
    "KBError",
    "UnknownKeyError",
    "WrongKindError",
    "check_file",
    "derive_text",
    "facts",
    "file_kind",
    "iter_kb_files",
    "load_object",
    "load_problem",
    "load_robot",
    "parse_term",
    "parse_yaml",
    "position_class",
    "read_kb",
    "read_yaml",
    "sanity",
    "term_text",
]
