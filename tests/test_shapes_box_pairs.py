"""world.parts.clip._box_pairs (the face overlap's candidate triangle pairs) against the
plain all-pairs test: the same pairs, on boxes of mixed sizes, slivers spanning many cells,
touching edges and degenerate (zero-width) boxes."""
from __future__ import annotations

import numpy as np
import pytest

from spar_py.world.parts.clip import _box_pairs


def _brute(alo: np.ndarray, ahi: np.ndarray, blo: np.ndarray, bhi: np.ndarray) -> set[tuple[int, int]]:
    return {(i, j) for i in range(len(alo)) for j in range(len(blo))
            if all(alo[i, k] <= bhi[j, k] and ahi[i, k] >= blo[j, k] for k in range(2))}


def _boxes(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    lo = rng.uniform(0, 10, (n, 2))
    size = rng.exponential(0.3, (n, 2))
    size[rng.random(n) < 0.05, 0] = 12.0  # slivers across the whole set
    size[rng.random(n) < 0.05] = 0.0      # points
    return lo, lo + size


@pytest.mark.parametrize("seed", range(5))
def test_box_pairs_are_the_meeting_pairs(seed: int) -> None:
    rng = np.random.default_rng(seed)
    alo, ahi = _boxes(rng, 300)
    blo, bhi = _boxes(rng, 120)
    ii, jj = _box_pairs(alo, ahi, blo, bhi)
    got = list(zip(ii.tolist(), jj.tolist()))
    assert len(got) == len(set(got))
    assert set(got) == _brute(alo, ahi, blo, bhi)
    assert got == sorted(got, key=lambda p: (p[1], p[0]))


def test_box_pairs_touching_and_empty() -> None:
    a = np.array([[0.0, 0.0], [2.0, 0.0]]), np.array([[1.0, 1.0], [3.0, 1.0]])
    b = np.array([[1.0, 1.0]]), np.array([[2.0, 2.0]])  # touches both at a corner
    ii, jj = _box_pairs(a[0], a[1], b[0], b[1])
    assert sorted(zip(ii.tolist(), jj.tolist())) == [(0, 0), (1, 0)]
    ii, jj = _box_pairs(a[0], a[1], np.zeros((0, 2)), np.zeros((0, 2)))
    assert len(ii) == 0 and len(jj) == 0
