"""Which body pairs a scene state checks (:func:`pair_structure`), from the bodies' names, frames
and kinds alone: non-adjacent links, the gripper against links 0..5, the tool's bodies against the
links, every moving body against the world's; the robot's allowed pairs and a state's own contacts
skipped, the gripper and the part it closes on left to the grasp rule (state.py). Kept in the
cell's cache.
"""
from __future__ import annotations

from typing import Any, Protocol

import numpy as np

from spar_py.world.collision.bodies import TOOL, WORLD, Body, body_columns
from spar_py.world.robot import TOOL_BODY

__all__ = ["GRIPPER_NAMES", "PAIRS_LIMIT", "PairRules", "STRUCTURES_LIMIT", "pair_structure", "part_of"]

#: Bound of the cell cache's table of checked pairs per arrangement of body names (a state's
#: bodies, allowed contacts, attached parts).
PAIRS_LIMIT = 256
#: Bound of the cell cache's table of whole pair structures (pair_structure's answers, by the
#: head's key and the world's body names: some kB each, up to some 100 kB for a generated
#: cell of hundreds of part bodies).
STRUCTURES_LIMIT = 256
#: The gripper's bodies (robots.py's palm and finger boxes and the tool body behind the palm),
#: checked against the part it closes on by the grasp rule, not by a pair.
GRIPPER_NAMES = frozenset({"palm", "finger_l", "finger_r", TOOL_BODY})


class PairRules(Protocol):
    """What :func:`pair_structure` reads of a scene (scene.py's CollisionScene)."""

    #: the robot's allowed pairs of body names (each a frozenset of two), never checked
    allowed: frozenset
    #: the cell's memo (core.memo.Memo) or None
    memo: Any


def pair_structure(scene: PairRules, bodies: list[Body], n_moving: int, hand_part: str | None,
                   allow: frozenset, attached: frozenset,
                   columns: tuple[list[str], np.ndarray, np.ndarray] | None = None
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, tuple]:
    """Which body pairs a state checks (see the module notes), from the bodies' names, frames and
    kinds alone (``bodies`` moving first, ``n_moving`` of them): (pairs (p, 2), table-checked
    moving bodies, pairs of two capsules (their bound is exact), pairs rigid with the flange).

    Pairs in the order of a loop over the moving bodies i and, within, all bodies j > i (a
    (moving, body) bool matrix read row by row). The columns of the world's bodies (frame WORLD,
    after the moving ones: obstacles and parts, most of a generated cell's bodies) depend only
    on the moving body and the world body's name, and are set a name at a time for all of them;
    the rest (links, gripper, tool parts: the same at most steps) come from
    :func:`_head_structure`, kept in the cell's cache."""
    names, frames, is_cap = body_columns(bodies)[3:] if columns is None else columns
    world_col = frames == WORLD
    world_col[:n_moving] = False
    head_cols = np.flatnonzero(~world_col)
    skip = scene.allowed | allow
    hkey = (tuple((names[j], int(frames[j]), bodies[j].kind) for j in head_cols.tolist()), head_cols.tobytes(),
            n_moving, hand_part, skip, attached)
    table = scene.memo.table("collision.pairs", PAIRS_LIMIT) if scene.memo is not None else None
    # the whole answer, by what it is made of (the head's key, the world's names in order and
    # every body's kind of bound): the requirement states of phase 1 (one per grasp, in a
    # world of obstacles alone) ask the same few structures again and again
    wcols = np.flatnonzero(world_col)
    fkey = (hkey, len(bodies), tuple(names[j] for j in wcols.tolist()), is_cap.tobytes())
    whole = scene.memo.table("collision.structures", STRUCTURES_LIMIT) if scene.memo is not None else None
    done = whole.get(fkey) if whole is not None else None
    if done is not None:
        return done
    head = table.get(hkey) if table is not None else None
    if head is None:
        head = _head_structure([bodies[j] for j in head_cols.tolist()], n_moving, hand_part, skip, attached)
        if table is not None:
            table[hkey] = head
    block, table_bodies, fixed_in_tool, excluded = head
    M = np.zeros((n_moving, len(bodies)), dtype=bool)
    M[:, head_cols] = block
    if len(wcols) and n_moving:
        index: dict[str, int] = {}
        ids = np.array([index.setdefault(names[j], len(index)) for j in wcols.tolist()], dtype=int)
        ok = np.ones((n_moving, len(index)), dtype=bool)   # (moving body, world name) checked
        ok[fixed_in_tool] = False
        for i, ex in enumerate(excluded):
            for n in ex:
                if n in index:
                    ok[i, index[n]] = False
        if hand_part is not None:  # the gripper against the part it closes on: the grasp rule
            grip = [i for i in range(n_moving) if names[i] in GRIPPER_NAMES]
            # the world's bodies are named by their part (only the tool's have "held:")
            hand_ids = [index[n] for n in (hand_part, f"held:{hand_part}") if n in index]
            ok[np.ix_(grip, hand_ids)] = False
        M[:, wcols] = ok[:, ids]
    pairs_arr = np.argwhere(M).astype(int).reshape(-1, 2)
    in_hand = (frames == 6) | (frames == TOOL)
    pi, pj = pairs_arr[:, 0], pairs_arr[:, 1]
    exact_pair = is_cap[pi] & is_cap[pj]
    rigid = tuple(np.flatnonzero(in_hand[pi] & in_hand[pj]).tolist())
    out = (pairs_arr, table_bodies, exact_pair, rigid)
    if whole is not None:  # shared by the states that ask it again: read-only
        for a in out[:3]:
            a.setflags(write=False)
        whole[fkey] = out
    return out


def part_of(name: str) -> str:
    """The part a body belongs to: its name, less the "held:" of the part in the hand."""
    return name[5:] if name.startswith("held:") else name


def _head_structure(head: list[Body], n_moving: int, hand_part: str | None, skip: frozenset,
                    attached: frozenset) -> tuple[np.ndarray, np.ndarray, list[int], list[frozenset]]:
    """The part of :func:`pair_structure` that does not depend on the world's bodies: for the
    bodies ``head`` (the moving ones first, ``n_moving`` of them, then the others that are not
    the world's: links on the base), the (moving, head body) matrix of checked pairs, the
    table-checked moving bodies, the moving bodies fixed in the tool (attached parts: checked
    against the arm and the gripper only, not the table they rest on nor the world) and, per
    moving body, the names of world bodies it is not checked against (itself, and its
    ``skip`` partners: the robot's allowed pairs and the state's ``allow``)."""
    moving = head[:n_moving]
    block = np.zeros((n_moving, len(head)), dtype=bool)
    # an attached part is a part of the world that happens to be where the tool is: it is
    # checked against the arm and the gripper only (not the table it rests on, nor the rest)
    fixed_in_tool = [i for i, b in enumerate(moving) if b.frame == TOOL and b.name in attached]
    fixed = set(fixed_in_tool)
    for i, bi in enumerate(moving):
        for j, bj in enumerate(head):
            if j <= i and j < n_moving:
                continue
            if frozenset((bi.name, bj.name)) in skip or bi.name == bj.name:
                continue
            if i in fixed and (bj.frame == WORLD or j in fixed):
                continue
            if bj.frame == WORLD or bj.frame == 0 and bi.frame >= 2:
                if bi.name in GRIPPER_NAMES and part_of(bj.name) == hand_part and bj.frame == WORLD:
                    continue  # the grasp rule decides
                block[i, j] = True
                continue
            if bj.frame == WORLD or bj.frame == 0:
                continue
            fi, fj = bi.frame, bj.frame
            ti, tj = bi.frame == TOOL, bj.frame == TOOL
            if ti and tj:  # in the hand: gripper and the hand's part by the grasp rule
                ni, nj = part_of(bi.name), part_of(bj.name)
                if ni in GRIPPER_NAMES and nj in GRIPPER_NAMES or ni == nj:
                    continue
                if hand_part in (ni, nj) and (ni in GRIPPER_NAMES or nj in GRIPPER_NAMES):
                    continue
                block[i, j] = True
                continue
            if ti or tj:
                link = bj if ti else bi
                other = bi if ti else bj
                limit = 5 if other.name in GRIPPER_NAMES else 6
                if link.frame <= limit:
                    block[i, j] = True
                continue
            if abs(fi - fj) >= 2:
                block[i, j] = True
    table_bodies = np.array([i for i, b in enumerate(moving)
                             if frozenset((b.name, "table")) not in skip and i not in fixed], dtype=int)
    excluded = [frozenset({b.name} | {n for p in skip if len(p) == 2 and b.name in p for n in p}) for b in moving]
    return block, table_bodies, fixed_in_tool, excluded
