"""The world layer: the geometry past the paper, in rooms the phases ask questions of.

Each room is a subpackage whose ``__init__`` is its door (``__all__``): code outside a room
imports from the door only (tests/test_structure.py checks it).

- ``robot``      robot models (DH tables, URDF import), the one gripper type, link shapes,
                 and ``ik`` (closed-form PUMA and UR families, a numeric fallback)
- ``parts``      part models from meshes and primitives: faces, stable poses, grasps,
                 features, the derivation cache
- ``collision``  one collision scene per cell: links, gripper, held part, parts, obstacles,
                 table; clearance and the closest pair; the cell's kept answers (CellCache)
- ``reach``      "the arm reaches T, clear of the world": workspace checks, phase 1's arcs
                 (Sec. 5.2.4), put-down placements, supports
- ``motion``     transit/transfer joint paths (OMPL), approach and retreat lines
- ``product``    products: assembly derivation, goals and precedence, layout, hand access,
                 grasp reports, single-arm rules
- ``run``        (a module, its own door) one planning run's world: options, log and
                 ``arc_pairs``, phase 1's door; phase 2's is spar_py.planning.run.PlanRun

Rooms depend on each other in one direction: robot <- collision <- parts <- reach <-
{motion, product}; run sits on reach, collision and motion.

Frames: world Z up, table top z = 0; transforms 4x4, column vectors, ``T_world_obj``.
Units: lengths in the cell's unit (``Cell.unit``); constants written in the code are in mm
and converted where used (``spar_py.core.units``); angles in radians.
"""
