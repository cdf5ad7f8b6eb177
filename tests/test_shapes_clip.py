"""The batched polygon clipping and areas of world.parts.clip give exactly (bit for bit) what
the one-polygon functions give, so the derived grasps of every cell stay the same."""
from __future__ import annotations

import numpy as np

from spar_py.world.parts import clip as sd


def test_clip_many_and_area_centroid_many_equal_the_one_polygon_functions() -> None:
    rng = np.random.default_rng(3)
    pad = np.array([[-0.5, -0.7], [0.5, -0.7], [0.5, 0.0], [-0.5, 0.0]])
    for trial in range(60):
        tris = sd._ccw_all(rng.uniform(-1, 1, (40, 3, 2)))
        clip = pad if trial % 3 == 0 else sd._ccw_all(rng.uniform(-1, 1, (1, 3, 2)))[0]
        P, cnt = sd.clip_many(tris, np.full(len(tris), 3), clip)
        areas, cens = sd.area_centroid_many(P, cnt)
        for i, t in enumerate(tris):
            ref = sd._clip_convex(t, clip)
            assert [tuple(map(float, v)) for v in P[i, : cnt[i]]] == ref
            a, c = sd._area_centroid(ref)
            assert areas[i] == a and np.array_equal(cens[i], c)
    # some were cut, some kept whole, some dropped: the cases all occur
    assert {0, 3} <= set(cnt.tolist()) and cnt.max() > 3


def test_the_areas_are_the_shoelace_areas() -> None:
    """Own check: a unit square clipped by a triangle covering its lower-left half has area 1/2."""
    sq = np.array([[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]])
    P, cnt = sd.clip_many(sq, np.array([4]), [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0)])
    areas, cens = sd.area_centroid_many(P, cnt)
    assert cnt[0] == 3 and areas[0] == 0.5 and np.allclose(cens[0], [1 / 3, 1 / 3])
