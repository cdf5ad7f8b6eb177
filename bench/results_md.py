"""RESULTS.md editing shared by the benchmarks ``python -m bench --only NAME`` runs alone."""
from __future__ import annotations

__all__ = ["splice_section"]

#: The targets table's heading in RESULTS.md: a benchmark's target rows go at its end.
TARGETS = "## Targets (issue 7)"
#: Where a new section goes when RESULTS.md has none of its own yet (the first present).
ANCHORS = ("## Where the time goes (cProfile)", "<!-- Records:")


def splice_section(text: str, section_lines: list[str], head: str, row_prefix: str, rows: list[list[str]]) -> str:
    """RESULTS.md's ``text`` with a benchmark's section (``section_lines``, its first line
    ``head``) and its target rows (those starting ``row_prefix``) replaced: the section where it
    was (up to the next ``## `` heading or the records), else before the profiles (or at the end
    of the generated part); the rows at the end of the targets table."""
    section = "\n".join(section_lines).rstrip("\n") + "\n\n"
    text = "".join(ln for ln in text.splitlines(keepends=True) if not ln.startswith(row_prefix))
    table = "".join("| " + " | ".join(row) + " |\n" for row in rows)
    at = text.find(TARGETS)
    if at >= 0 and table:
        end = text.find("\n\n", text.find("|", at))  # the table's last line ends here
        text = text[:end + 1] + table + text[end + 1:]
    if head in text:
        start = text.index(head)
        nxt = text.find("\n## ", start + len(head))
        stop = [i for i in (nxt + 1 if nxt >= 0 else -1, text.find("<!-- Records:", start)) if i > 0]
        end = min(stop) if stop else len(text)
        return text[:start] + section + text[end:]
    for anchor in ANCHORS:
        if anchor in text:
            i = text.index(anchor)
            return text[:i] + section + text[i:]
    return text.rstrip("\n") + "\n\n" + section
