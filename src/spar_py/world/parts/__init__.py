"""The parts room: part models from meshes and primitives: the mesh (loaded and repaired), its faces and
features, stable poses, grasps (facets, antipodal pairs, shafts) and the derivation cache.

This is the room's door: code outside world/parts/ imports these names from here, never
from the modules behind it.
"""

from spar_py.world.parts.cache import (
    cache_dir, derive as derive_part, load as load_derivation, source_digest, store as store_derivation,
)
from spar_py.world.parts.grasps import check_entries, mate_grasp_usable
from spar_py.world.parts.hand import grasp_problem
from spar_py.world.parts.mesh import (
    Geometry, Primitive, assembly_transforms, axis_basis, derive_faces, face_of_point, load_mesh,
    part_mesh, poses_clear_of_table,
)
from spar_py.world.parts.shafts import fit_circle
from spar_py.world.parts.stable import stable_poses
from spar_py.world.robot import Gripper  # the one gripper type (the robot room's), as grasps are derived for it

__all__ = [
    "assembly_transforms", "axis_basis", "cache_dir", "check_entries", "derive_faces", "derive_part",
    "face_of_point", "fit_circle", "Geometry", "grasp_problem", "Gripper", "load_derivation",
    "load_mesh", "mate_grasp_usable", "part_mesh", "poses_clear_of_table", "Primitive", "source_digest",
    "stable_poses", "store_derivation",
]
