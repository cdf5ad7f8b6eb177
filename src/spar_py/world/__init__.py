"""The world layer: the geometry past the paper, in one place the phases ask questions of.

- ``shapes``     meshes and primitives: faces, stable poses, grasps, features, T_a derived
- ``robots``     robot models: DH tables, URDF import, link and gripper collision shapes
- ``ik``         closed-form IK families (PUMA, UR) and a numeric fallback, one interface
- ``collision``  one collision scene per run: links, gripper, held part, parts, obstacles,
                 table; clearance and the closest pair
- ``motion``     transit/transfer joint paths, approach and retreat
- ``workspace``  "the arm reaches T, clear of the world": what phase 1's arcs, the
                 placements and phase 2's steps (``arm_at``) ask
- ``placement``  where a put-down can go: the free table grid, and whether some placement
                 of it lets the arm reach a requirement (``some_placement_reaches``)
- ``arcs``       phase 1's reachable / mate_reachable arcs (Sec. 5.2.4), with the refusals
- ``run``        the door: a cell's kept answers (``CellCache``) and one planning run
                 (``WorldRun``: options, log, ``arc_pairs``); phase 2's door is
                 spar_py.planning.run.PlanRun, which holds a WorldRun

Frames: world Z up, table top z = 0; transforms 4x4, column vectors, ``T_world_obj``.
Units: lengths in the cell's unit (``Cell.unit``); constants written in the code are in mm
and converted where used (``spar_py.core.units``); angles in radians.
"""
