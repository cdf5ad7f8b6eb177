"""The product room: products of many parts: the assembly derivation from meshes (mates, insertion directions,
precedence by disassembly), the product's goals and precedence, the layout of the parts
on the table, hand access, grasp reports and the single-arm rules.

This is the room's door: code outside world/product/ imports these names from here, never
from the modules behind it.
"""

from spar_py.world.product.access import arm_clear_of, with_hand_access
from spar_py.world.product.compile import compile_product
from spar_py.world.product.assembly import AssemblyResult, Insertion, derive_assembly_cached
from spar_py.world.product.grasp_report import GraspReport, grasp_report
from spar_py.world.product.layout import layout_product
from spar_py.world.product.products import (
    AXIS_TOL_MM, axis_offset, compile_goals, feature_axis, insertion_pairs, link_directions, makers, mate_misalignment,
    near_parts, precedence, subassembly_poses, subtree, through_precedence, via_grasps,
)
from spar_py.world.product.single_arm import single_arm_report

__all__ = [
    "AXIS_TOL_MM", "arm_clear_of", "AssemblyResult", "axis_offset", "compile_goals", "compile_product",
    "derive_assembly_cached", "feature_axis", "grasp_report", "GraspReport", "Insertion", "insertion_pairs",
    "layout_product", "link_directions", "makers", "mate_misalignment", "near_parts",
    "precedence", "single_arm_report", "subassembly_poses", "subtree", "through_precedence", "via_grasps",
    "with_hand_access",
]
