"""bench/products.py's verdicts and its splice into RESULTS.md (``python -m bench --only products``):
the targets of issue 33 judged on the figures given, the section and rows replaced in place,
the rest of the file (other sections, the hand-written records) kept."""
from __future__ import annotations

from bench import products

TEXT = """# spar-py benchmarks

## Targets (issue 7)

| target | measured | verdict |
|---|---|---|
| IK | 1 us | met |

## Reading

text

## Where the time goes (cProfile)

profiles

<!-- Records: written by hand, kept by python -m bench -->
records
"""


def _figures(wall: float, mb: float) -> dict:
    side = {"wall_s": wall, "load_s": 0.5, "phase1_s": 0.3, "phase2_s": 0.1, "rss_peak_mb": mb, "process_s": wall + 1,
            "outcome": "plan", "outcomes": ["plan"], "actions": 40, "rows": 4, "cols": 5}
    row = {"n": 20, "runs": 3, "board": side, "pairs": dict(side, wall_s=0.7), "fd": {"error": "not installed"}}
    return {"rows": [row], "repeats": 3, "timeout_s": 300.0}


def test_verdicts_follow_the_targets() -> None:
    assert products.verdicts(_figures(1.8, 170))[20][0]
    assert not products.verdicts(_figures(10.5, 170))[20][0]   # over 10 s
    assert not products.verdicts(_figures(1.8, 501))[20][0]    # over 500 MB


def test_splice_replaces_in_place_and_keeps_the_rest() -> None:
    once = products.splice(TEXT, _figures(1.8, 170))
    assert once.count(products.SECTION) == 1 and once.count(products.TARGET_ROW) == 1
    assert once.index("| IK |") < once.index(products.TARGET_ROW) < once.index("## Reading")
    assert once.index(products.SECTION) < once.index("## Where the time goes") < once.index("records")
    again = products.splice(once, _figures(10.5, 170))
    assert again.count(products.SECTION) == 1 and again.count(products.TARGET_ROW) == 1
    assert "| NOT met |" in again and "10.50 s" in again and "1.80 s" not in again
    assert again == products.splice(TEXT, _figures(10.5, 170))  # the same as spliced into the bare file
    assert again.endswith("<!-- Records: written by hand, kept by python -m bench -->\nrecords\n")
