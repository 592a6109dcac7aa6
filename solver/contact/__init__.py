"""Self-contact: one home for the geometry (:mod:`.geometry`), the laws (:mod:`.laws`) and
the search, closest points and forces (:mod:`.model`). See docs/contact.md."""
from .geometry import (close_node_pairs, curve_basis, min_surface_gap, point_curve,
                       point_segment, segment_segment, swept_min_distance)
from .laws import BarrierLaw, SeedLaw, smoothstep_off
from .model import (EXCLUSION_DIAMETERS, GAP_FLOOR_FRACTION, ContactCandidates,
                    ContactEvaluation, SelfContact, assemble_nodal,
                    assemble_nodal_jacobian, nodal_weights)

__all__ = ["SelfContact", "ContactCandidates", "ContactEvaluation", "assemble_nodal",
           "assemble_nodal_jacobian",
           "nodal_weights", "SeedLaw", "BarrierLaw", "smoothstep_off", "point_segment",
           "point_curve", "curve_basis",
           "swept_min_distance", "close_node_pairs", "segment_segment", "min_surface_gap",
           "GAP_FLOOR_FRACTION",
           "EXCLUSION_DIAMETERS"]
