"""`Scene.bolus`: the settings the sidebar panel passes to the operators."""
from __future__ import annotations

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, StringProperty

from ..core.analysis.saliency import DEFAULT_SMOOTHING_MM

COLOR_BY_ITEMS = [
    ("FLATTENABILITY", "Flattenability", "varpi(v) = |theta - 2pi| of eq. 4-1: where the surface cannot lie flat (any angle excess or deficit)"),
    ("SALIENCY", "Saliency", "Segmentation saliency s(v) of eq. 4-4: angle excess only (would overlap when flattened); drives the cuts"),
]
METHOD_ITEMS = [
    ("KMEANS", "K-means", "Cluster the spectral embedding with k-means"),
    ("GMM", "Gaussian mixture", "Cluster the spectral embedding with a Gaussian mixture model"),
]


def smoothing_property(**kw):
    return FloatProperty(
        name="Smoothing",
        description=(
            "Analysis smoothing scale in mm: angle sums are measured on a copy smoothed at this scale, "
            "so scanner noise does not hide the shape (0 = raw mesh; the mesh itself never moves)"
        ),
        default=DEFAULT_SMOOTHING_MM,
        min=0.0,
        soft_max=20.0,
        precision=1,
        **kw,
    )


def patches_property(**kw):
    return IntProperty(name="Patches", description="Number of patches to segment into (spectral clusters)", default=3, min=1, max=64, soft_max=8, **kw)


def eta_property(**kw):
    return FloatProperty(
        name="Eta",
        description="Weight of the saliency term in the edge distance (eq. 4-5); 0 gives plain spectral clustering",
        default=5.0,
        min=0.0,
        soft_max=20.0,
        **kw,
    )


def seed_property(**kw):
    return IntProperty(name="Seed", description="Random seed of the eigen-solver start vector and the clustering", default=0, min=0, **kw)


def color_by_property(**kw):
    return EnumProperty(name="Colour by", items=COLOR_BY_ITEMS, default="FLATTENABILITY", **kw)


def method_property(**kw):
    return EnumProperty(name="Clustering", items=METHOD_ITEMS, default="KMEANS", **kw)


UNFOLD_METHODS = [
    ("LBFGS", "L-BFGS", "Minimise the crossed-spring energy with preconditioned L-BFGS, then refine lengths (default)"),
    ("EXPLICIT", "Explicit", "The seed's explicit mass-spring integration (slower)"),
]


def gap_property(**kw):
    return FloatProperty(name="Gap", description="Space between the islands of the pattern (mm)", default=10.0,
                         min=0.0, soft_max=100.0, **kw)


def unfold_method_property(**kw):
    return EnumProperty(name="Method", items=UNFOLD_METHODS, default="LBFGS", **kw)


def refine_property(**kw):
    return BoolProperty(name="Refine lengths", default=True,
                        description="Finish by minimising the absolute length error EL itself (reweighted least squares)",
                        **kw)


def seam_allowance_property(**kw):
    return FloatProperty(name="Seam allowance", description="Extra outline offset outward from every cut line (mm); 0 = none",
                         default=0.0, min=0.0, soft_max=20.0, **kw)


def max_el_property(**kw):
    return FloatProperty(
        name="Max EL",
        description=(
            "Largest length error (EL, %) a pattern piece may have: a patch that would exceed it gets darts at "
            "its dome points (nose tip, chin) and is split along its grooves until every piece meets it or the "
            "piece limit is reached; 0 = off (one piece per patch)"
        ),
        # no hard minimum: a negative value from a script is refused with a message, not clamped to "off"
        default=2.0, soft_min=0.0, soft_max=10.0, precision=1, subtype="PERCENTAGE", **kw,
    )


def sheet_thickness_property(**kw):
    return FloatProperty(
        name="Sheet thickness",
        description=(
            "Thickness of the bolus sheet in mm: the pattern is unfolded from the mid-surface (the skin moved out "
            "by half of it) and every piece gets its bending strain and a sheet-or-print advice; 0 = unfold the "
            "skin itself"
        ),
        default=0.0, soft_min=0.0, soft_max=20.0, precision=1, **kw,
    )


IMPROVE_METHODS = [
    ("GRADIENT", "Gradient", "Projected L-BFGS-B on the offsets, on the smoothed objective of eq. 4-21 (fast)"),
    ("LPSO", "L-PSO", "The seed's local particle swarm (Algorithms 4-1, 4-2) on the objective of eq. 4-21 (seeded)"),
]


def max_gap_property(**kw):
    return FloatProperty(
        name="Max air gap",
        description=(
            "Largest distance in mm a vertex may move outward along its normal, i.e. the largest air gap "
            "between the skin and a bolus shaped to the improved surface (about 1 mm is clinically acceptable)"
        ),
        # no hard minimum: 0 or a negative value from a script is refused with a message, not clamped
        default=1.0, soft_min=0.1, soft_max=5.0, precision=2, **kw,
    )


def improve_method_property(**kw):
    return EnumProperty(name="Optimiser", items=IMPROVE_METHODS, default="GRADIENT", **kw)


PAGE_ITEMS = [
    ("NONE", "One page", "PDF: one page the size of the whole pattern (for a plotter or a large-format printer)"),
    ("A4", "A4 tiles", "PDF: tiled on A4 pages with overlap and alignment marks"),
    ("LETTER", "Letter tiles", "PDF: tiled on US Letter pages with overlap and alignment marks"),
]


def page_property(**kw):
    return EnumProperty(name="Pages", items=PAGE_ITEMS, default="NONE", **kw)


def warn_distortion_property(**kw):
    return FloatProperty(
        name="Warn above",
        description=(
            "A pattern piece whose length or area error (EL or EA) is above this percentage, or that has "
            "flipped or overlapping triangles, gets a warning with its figures and what to do about it"
        ),
        default=3.0, min=0.0, soft_max=20.0, precision=1, subtype="PERCENTAGE", **kw,
    )


RETRIEVE_METHODS = [
    ("VIEWS", "Views", "The model's silhouettes from 40 directions against the photo's (default)"),
    ("SKELETON", "Skeleton", "Feature skeletons and ICP, the seed's chapter 5 (for comparison)"),
]
PRINT_METHODS = [
    ("ABCUT", "ABcut", "Area-balanced spectral cut (seed 6.2): parts of similar area (default)"),
    ("RATIOCUT", "RatioCut", "Plain spectral cut, the seed's 'traditional method' (for comparison)"),
    ("LEARNED", "Learned", "Stacked auto-encoder + affinity propagation (seed 6.4): the number of parts comes from "
                           "the surface's printing features, Parts is not used (a second opinion)"),
]


def parts_property(**kw):
    return IntProperty(name="Parts", description="Number of print parts to split the bolus into", default=3, min=1,
                       max=64, soft_max=8, **kw)


def print_method_property(**kw):
    return EnumProperty(name="Cut", items=PRINT_METHODS, default="ABCUT", **kw)


def layer_property(**kw):
    return FloatProperty(name="Layer height", description="Printer layer height in mm (cusp height, eq. 6-1)",
                         default=0.2, min=0.01, soft_max=1.0, precision=2, **kw)


def skin_side_up_property(**kw):
    return BoolProperty(
        name="Skin side up",
        description=(
            "Only print directions that keep the skin-contact side (the side the surface normals point away "
            "from) facing up, so no support touches it"
        ),
        default=False,
        **kw,
    )


LEFT_AXIS_ITEMS = [
    ("+X", "+X (DICOM / LPS)", "The patient's left is +X, as in DICOM (LPS) coordinates (default)"),
    ("-X", "-X (RAS)", "The patient's left is -X, as in RAS coordinates (3D Slicer, NIfTI)"),
]


def thickness_property(**kw):
    return FloatProperty(name="Thickness", description="Bolus thickness in mm: the outer face's true distance "
                         "from the skin (typically 5-20 mm; at most 50)", default=10.0, soft_min=1.0, soft_max=30.0,
                         precision=1, **kw)


def clearance_property(**kw):
    return FloatProperty(name="Clearance", description="Gap in mm between the skin and the bolus's inner face "
                         "(0 = the inner face follows the skin)", default=0.0, soft_min=0.0, soft_max=5.0, precision=2,
                         **kw)


def resolution_property(**kw):
    return FloatProperty(name="Resolution", description="Voxel size in mm of the distance field the solid is "
                         "built from: finer is more exact and slower (0.5 mm: a few ten seconds on a face region)",
                         default=0.5, soft_min=0.2, soft_max=2.0, precision=2, **kw)


def label_property(**kw):  # also the ID printed on every pattern piece (export_pattern)
    return StringProperty(name="Label", description="Text engraved 0.6 mm deep on the bolus's outer face (e.g. a "
                          "patient ID; each print part gets '<label> <part>') with L / R markers; empty = none",
                          default="", **kw)


def density_property(**kw):
    return FloatProperty(name="Density", description="Density of the print material in g/cm³, for the bolus's "
                         "mass (1.04: tissue-equivalent filament)", default=1.04, min=0.01, soft_min=0.5,
                         soft_max=3.0, precision=2, **kw)


def connector_clearance_property(**kw):
    return FloatProperty(name="Connector clearance", description="Gap in mm between a connector's peg and its "
                         "hole (the hole's radius and depth exceed the peg's by this much)", default=0.2, soft_min=0.0,
                         soft_max=1.0, precision=2, **kw)


def left_axis_property(**kw):
    return EnumProperty(name="Patient left", description="The world axis pointing to the patient's left, "
                        "for the L / R markers", items=LEFT_AXIS_ITEMS, default="+X", **kw)


def area_radius_property(**kw):
    return FloatProperty(name="Radius", description="Treatment area: the faces within this distance in mm of the 3D "
                         "cursor, measured along the surface", default=45.0, min=0.0, soft_min=5.0, soft_max=150.0,
                         precision=1, **kw)


def exclude_cavities_property(**kw):
    return BoolProperty(name="Leave out cavities", description="Leave out faces that cannot be seen from outside "
                        "(inside the nostrils, an ear canal): they become holes of the area", default=True, **kw)


def time_limit_property(**kw):
    return FloatProperty(name="Time limit (s)", description="A long step stops at this limit with nothing changed "
                         "(and says how far it got); one that cannot fit in it at all (its least time, estimated from "
                         "the mesh size) is refused before it starts with what to do instead (a smaller area, Decimate, "
                         "a coarser resolution); 0: no limit (Esc cancels a step from the sidebar)",
                         default=60.0, min=0.0, soft_max=600.0, step=1000, precision=0, **kw)


class BolusSettings(bpy.types.PropertyGroup):
    area_radius_mm: area_radius_property()
    exclude_cavities: exclude_cavities_property()
    smoothing_mm: smoothing_property()
    color_by: color_by_property()
    patches: patches_property()
    eta: eta_property()
    seed: seed_property()
    method: method_property()
    max_gap_mm: max_gap_property()
    improve_method: improve_method_property()
    unfold_method: unfold_method_property()
    refine: refine_property()
    gap_mm: gap_property()
    max_el_pct: max_el_property()
    sheet_thickness_mm: sheet_thickness_property()
    page: page_property()
    seam_allowance_mm: seam_allowance_property()
    warn_distortion_pct: warn_distortion_property()
    parts: parts_property()
    print_method: print_method_property()
    layer_mm: layer_property()
    skin_side_up: skin_side_up_property()
    thickness_mm: thickness_property()
    clearance_mm: clearance_property()
    resolution_mm: resolution_property()
    label: label_property()
    density_g_cm3: density_property()
    connector_clearance_mm: connector_clearance_property()
    left_axis: left_axis_property()
    time_limit_s: time_limit_property()
    library_dir: StringProperty(name="Library", subtype="DIR_PATH", default="",
                                description="Folder of bolus models (.blend, .stl, .obj) to find a match in")
    photo_path: StringProperty(name="Photo", subtype="FILE_PATH", default="",
                               description="Photo of the treatment site or of a bolus (PNG, JPEG, ...)")
    retrieve_method: EnumProperty(name="Method", items=RETRIEVE_METHODS, default="VIEWS")
    retrieve_count: IntProperty(name="Matches", description="How many of the best matches to list", default=5,
                                min=1, soft_max=20)
