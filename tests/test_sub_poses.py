"""Issue 33 item 4: a subassembly has its own stable poses (of the combined shape). Own check:
each pose rests the union of the parts' meshes (at the product file's poses) on the table, with
its centre of mass strictly over the support polygon, in a down direction the root alone has no
pose in; kb/products gives them to the root's model and records the subtree they need."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import ConvexHull

from spar_py.kb.products import load_product
from spar_py.world.products import subassembly_poses
from spar_py.world.shapes import part_mesh

ROOT = Path(__file__).resolve().parent.parent


def test_disc_with_pin_rests_on_its_side_on_the_pin_and_rim() -> None:
    product = load_product(ROOT / "kb/products/disc_pin.yaml", "mm")
    got = subassembly_poses(product, "mm", use_cache=False)
    assert sorted(got) == ["disc"]
    assert got["disc"], "the disc with its pin has stable poses of its own"
    meshes = [part_mesh(product.parts[p].model).copy().apply_transform(product.parts[p].pose)
              for p in ("disc", "pin")]
    V = np.vstack([m.vertices for m in meshes])
    com = sum(m.center_mass * m.volume for m in meshes) / sum(m.volume for m in meshes)
    disc = product.parts["disc"].model
    own_down = [np.asarray(p.R, float)[2] for label, p in disc.poses.items() if "_sub_p" not in label]
    assert len(own_down) == 2  # the disc alone: flat on either face
    for s in got["disc"]:
        np.testing.assert_allclose(s.R @ s.R.T, np.eye(3), atol=1e-9)
        W = V @ s.R.T
        W[:, 2] += s.height
        assert abs(W[:, 2].min()) < 1e-6  # on the table, nothing below it
        pin_low = (meshes[1].vertices @ s.R.T)[:, 2].min() + s.height
        assert abs(pin_low) < 1e-6, (s.label, pin_low)  # the pin carries it too
        low = W[W[:, 2] < 1e-6][:, :2]
        c = (s.R @ com)[:2]
        hull = ConvexHull(low)
        assert (hull.equations[:, :2] @ c + hull.equations[:, 2] < -1e-9).all(), (s.label, c)
        assert not any(np.allclose(s.R[2], d, atol=1e-6) for d in own_down)
        # wired in: the disc's model has the pose, at that height, and it needs the pin
        sp = disc.poses[s.label]
        np.testing.assert_allclose(sp.R, s.R)
        assert sp.height == s.height and sp.rfaces
        assert product.sub_poses["disc"][s.label] == ("pin",)
    # one of them on its side (the L of the pin's head and tip and the disc's rim): the disc's
    # axis (nearly) flat, the disc's rim down too
    side = [s for s in got["disc"] if abs(s.R[2, 2]) < 0.2]
    assert side
    for s in side:
        assert abs((meshes[0].vertices @ s.R.T)[:, 2].min() + s.height) < 1e-6


def test_sub_poses_are_cached_by_content_and_a_hit_builds_no_mesh(tmp_path, monkeypatch) -> None:
    """A second call with the same parts reads the poses back (same labels, R, heights, resting
    faces) without building any part's mesh; a changed relative pose misses."""
    from spar_py.world import shapes

    monkeypatch.setenv("SPAR_CACHE_DIR", str(tmp_path))
    product = load_product(ROOT / "kb/products/disc_pin.yaml", "mm")
    first = subassembly_poses(product, "mm")
    assert len(list(tmp_path.glob("subposes-*.json"))) == 1

    def no_mesh(self):
        raise AssertionError("a cache hit built a mesh")

    monkeypatch.setattr(shapes.Geometry, "mesh", no_mesh)
    again = subassembly_poses(product, "mm")
    assert [s.label for s in again["disc"]] == [s.label for s in first["disc"]]
    for a, b in zip(again["disc"], first["disc"]):
        np.testing.assert_allclose(a.R, b.R, atol=1e-12)
        assert a.height == b.height and a.prob == b.prob and a.rfaces == b.rfaces and a.rfaces
    moved = product.parts["pin"].pose.copy()
    moved[0, 3] += 1.0
    product.parts["pin"] = type(product.parts["pin"])(**{**product.parts["pin"].__dict__, "pose": moved})
    with pytest.raises(AssertionError, match="built a mesh"):
        subassembly_poses(product, "mm")
