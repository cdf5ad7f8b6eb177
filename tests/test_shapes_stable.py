"""world.parts.stable's stable poses against trimesh's own compute_stable_poses (the
reference it reimplements with arrays): the same poses as a set, each transform within 1e-9 of
its match and with its probability within 1e-9, on boxes, cylinders, spheres, an off-centre
mass, unions of shapes and a Fabrica part's hull.

Not bit for bit nor in trimesh's order: the last bits of the static probabilities depend on
the processor's and BLAS's kernels, and poses of (nearly) equal probability then come out of
the final argsort in another order (a cylinder's sides, a sphere's faces). Each pose of ours is
matched to the nearest unmatched pose of trimesh's instead; the test below the comparisons
shows that a dropped pose or one moved by 1e-6 still fails."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from spar_py.world.parts.stable import stable_poses

FABRICA = Path(__file__).resolve().parents[1] / "kb" / "products" / "fabrica"
TOL = 1e-9  # on each entry of a transform, and on a probability


def _bodies() -> list[tuple[trimesh.Trimesh, np.ndarray]]:
    box = trimesh.creation.box((1.0, 2.0, 3.0))
    cyl = trimesh.creation.cylinder(1.0, 2.0, sections=48)
    sph = trimesh.creation.icosphere(3)
    lshape = trimesh.util.concatenate([box, trimesh.creation.box((3.0, 0.5, 0.5)).apply_translation((1.5, 0, -1.25))])
    out = [(m, m.center_mass) for m in (box, cyl, sph, lshape, trimesh.creation.capsule(2.0, 0.5))]
    out.append((cyl, cyl.center_mass + np.array([0.3, 0.1, 0.4])))
    return out


def _fabrica(name: str) -> tuple[trimesh.Trimesh, np.ndarray]:
    hull = trimesh.load(FABRICA / name, force="mesh").convex_hull
    return hull, hull.center_mass


def _mismatches(T: np.ndarray, P: np.ndarray, T_ref: np.ndarray, P_ref: np.ndarray) -> list[str]:
    """What keeps (T, P) from being the poses (T_ref, P_ref) in some order: each pose of ours
    takes the nearest reference pose not yet taken (largest entry difference of the 4x4
    transforms), which must lie within TOL and carry a probability within TOL; every reference
    pose must be taken. (Distinct poses differ by far more than TOL: trimesh merges normals
    equal to 3 decimals into one pose.) Empty when they are the same set."""
    out = []
    if len(T) != len(T_ref):
        out.append(f"{len(T)} poses, trimesh has {len(T_ref)}")
    free = np.ones(len(T_ref), bool)
    for i in range(len(T)):
        d = np.abs(T_ref - T[i]).max(axis=(1, 2))
        d[~free] = np.inf
        j = int(np.argmin(d)) if free.any() else -1
        if j < 0 or d[j] > TOL:
            out.append(f"pose {i} matches none of trimesh's (nearest differs by {d[j] if j >= 0 else np.inf:.3g})")
            continue
        free[j] = False
        if abs(P[i] - P_ref[j]) > TOL:
            out.append(f"pose {i}: probability {P[i]!r}, trimesh's {P_ref[j]!r}")
    out += [f"trimesh's pose {j} matches none of ours" for j in np.flatnonzero(free)]
    return out


def _ours_and_trimesh(body: trimesh.Trimesh, com: np.ndarray) -> tuple[np.ndarray, ...]:
    hull = body.convex_hull
    T_ref, P_ref = trimesh.poses.compute_stable_poses(hull, center_mass=com, sigma=0.0, n_samples=1)
    T, P = stable_poses(hull, com)
    return T, P, T_ref, P_ref


@pytest.mark.parametrize("k", range(6))
def test_stable_poses_match_trimesh(k: int) -> None:
    T, P, T_ref, P_ref = _ours_and_trimesh(*_bodies()[k])
    assert len(T) > 0
    assert _mismatches(T, P, T_ref, P_ref) == []
    assert np.all(np.diff(P) <= 0)  # ours: the most probable first


@pytest.mark.parametrize("name", ["stool_circular/0.ply", "gamepad/1.ply"])
def test_stable_poses_match_trimesh_on_a_scanned_hull(name: str) -> None:
    T, P, T_ref, P_ref = _ours_and_trimesh(*_fabrica(name))
    assert len(T) > 1
    assert _mismatches(T, P, T_ref, P_ref) == []
    assert np.all(np.diff(P) <= 0)


def test_the_comparison_fails_on_a_dropped_or_moved_pose() -> None:
    """The matching is order-free, yet a pose dropped (from either side), a transform entry
    moved by 1e-6, or a probability moved by 1e-6 each make it fail."""
    T, P, T_ref, P_ref = _ours_and_trimesh(*_fabrica("gamepad/1.ply"))
    assert len(T) > 10 and _mismatches(T, P, T_ref, P_ref) == []
    flip = np.random.default_rng(0).permutation(len(T_ref))
    assert _mismatches(T, P, T_ref[flip], P_ref[flip]) == []
    assert _mismatches(T[1:], P[1:], T_ref, P_ref) != []
    assert _mismatches(T, P, T_ref[:-1], P_ref[:-1]) != []
    for r, c in ((0, 0), (2, 1), (2, 3)):  # a rotation entry, the z axis, the lift off the table
        moved = T.copy()
        moved[5, r, c] += 1e-6
        assert _mismatches(moved, P, T_ref, P_ref) != [], (r, c)
    moved_p = P.copy()
    moved_p[5] += 1e-6
    assert _mismatches(T, moved_p, T_ref, P_ref) != []
