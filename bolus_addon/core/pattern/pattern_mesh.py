"""The pattern object's numbers: islands, polygons, stored positions and piece rows (seed 4.5, SPEC).

What the unfold and export operators need between reading the mesh and writing it
back, as arrays in and arrays out (no Blender):

* `patch_islands` - one island per connected piece of a patch (a patch cut in two by
  the region, or edited, unfolds as two pieces);
* `pattern_polygons` - the source polygons of the islands with their corners mapped to
  the pattern vertex their triangles use there (a vertex on a cut appears twice);
* `stored_positions` - the pattern positions as the mesh stores them (float32 scene
  units), and back in mm, so the reported EL / EA are those of the stored pattern;
* `build_pattern` - lay the unfolded islands out and measure them as SPEC does
  (EL / EA of eqs. 3-30 / 3-31 over the polygons, n-gons fanned from the first corner);
* `piece_rows` / `diagnose_pieces` / `piece_warning` / `pattern_messages` - the pattern
  table, one row per island with its figures and advice, and the messages for the user
  as structured data ``(level, text)``: nothing is parsed back out of text;
* `svg_pieces` - the pattern object's triangles grouped by patch for `pattern_svg`.

Vertex arrays are in mm unless said otherwise.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field

import numpy as np

from ..unfold.assemble import assemble_pattern
from ..errors import BolusError
from ..unfold.measures import polygon_area_error, polygon_errors
from ..unfold.mid_surface import SHEET_RADIUS_FACTOR
from ..unfold.overlap import as_pattern_arrays, signed_areas
from ..unfold.piece_advice import DEFAULT_WARN_FRACTION, piece_advice
from ..analysis.saliency import DEFAULT_SMOOTHING_MM
from ..mesh.topology import MeshTopology, check_mesh, face_areas, submesh
from .islands import PatchIslands, patch_islands, SheetLayout, collect_pieces  # noqa: F401 (re-exported)

__all__ = [
    "PatchIslands",
    "SheetLayout",
    "collect_pieces",
    "PatternPolygons",
    "PatternBuild",
    "patch_islands",
    "pattern_polygons",
    "stored_positions",
    "build_pattern",
    "piece_rows",
    "diagnose_pieces",
    "piece_warning",
    "pattern_messages",
    "svg_pieces",
    "export_pieces",
    "table_rows",
    "add_sheet_figures",
    "sheet_messages",
]


@dataclass
class PatternPolygons:
    """polys (p,) source polygon ids; sizes (p,) corners per polygon; corner_src (c,) the
    region vertex (row of V) of every corner; corner_pat (c,) its pattern vertex."""

    polys: np.ndarray
    sizes: np.ndarray
    corner_src: np.ndarray
    corner_pat: np.ndarray

    @property
    def loop_starts(self) -> np.ndarray:
        """(p,) first corner of every polygon in the corner arrays."""
        return np.concatenate([[0], np.cumsum(self.sizes)[:-1]]).astype(np.int64)


def pattern_polygons(tri_poly, tri_island, F, F_pat, vert_ids, loop_start, loop_total, loop_vert) -> PatternPolygons:
    """The source polygons whose triangles all lie in islands, with their corners mapped to the pattern.

    Parameters
    ----------
    tri_poly : (m,) int - source polygon of every region triangle
    tri_island : (m,) int - island of every region triangle, -1 outside
    F : (m,3) int - region triangles (rows of the region's V)
    F_pat : (m,3) int - the pattern vertex of every corner of those triangles (rows < 0 outside)
    vert_ids : (n,) int, sorted - the mesh vertex of every region vertex
    loop_start, loop_total : (P,) int - first corner and corner count of every mesh polygon
    loop_vert : (L,) int - mesh vertex of every mesh corner

    Returns
    -------
    PatternPolygons in increasing polygon order, corners in the source's corner order.
    """
    tri_poly = np.asarray(tri_poly, dtype=np.int64)
    tri_island = np.asarray(tri_island, dtype=np.int64)
    loop_start = np.asarray(loop_start, dtype=np.int64)
    loop_total = np.asarray(loop_total, dtype=np.int64)
    loop_vert = np.asarray(loop_vert, dtype=np.int64)
    vert_ids = np.asarray(vert_ids, dtype=np.int64)
    lowest = np.full(len(loop_start), np.iinfo(np.int64).max)
    np.minimum.at(lowest, tri_poly, tri_island)
    highest = np.full(len(loop_start), -1)
    np.maximum.at(highest, tri_poly, tri_island)
    polys = np.unique(tri_poly)
    polys = polys[lowest[polys] >= 0]
    torn = polys[highest[polys] != lowest[polys]]
    if len(torn):  # a dart or split along a quad's diagonal would tear the polygon apart
        raise BolusError(f"internal error: polygon {int(torn[0])} lies in two pattern pieces")
    sizes = loop_total[polys]
    first = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)
    corner_loop = np.repeat(loop_start[polys] - first, sizes) + np.arange(sizes.sum())
    corner_mesh = loop_vert[corner_loop]
    corner_src = np.searchsorted(vert_ids, corner_mesh)
    if np.any(corner_src >= len(vert_ids)) or np.any(vert_ids[np.minimum(corner_src, len(vert_ids) - 1)]
                                                     != corner_mesh):
        raise BolusError("internal error: a polygon corner is not a vertex of the region")
    keep = tri_island >= 0
    n = max(len(vert_ids), 1)
    key = np.repeat(tri_poly[keep], 3) * n + np.asarray(F, dtype=np.int64)[keep].ravel()
    ukey, first_use = np.unique(key, return_index=True)
    pat_of_key = np.asarray(F_pat, dtype=np.int64)[keep].ravel()[first_use]
    corner_pat = pat_of_key[np.searchsorted(ukey, np.repeat(polys, sizes) * n + corner_src)]
    return PatternPolygons(polys, sizes, corner_src, corner_pat)


def stored_positions(UV, mm_per_unit: float) -> tuple[np.ndarray, np.ndarray]:
    """The pattern as a mesh stores it: ``(co (n,3) float32 scene units at z = 0, UV (n,2) float64 mm)``.

    UV (n,2) mm.  The returned mm positions are the float32 ones converted back, so the
    errors measured on them are those of the stored pattern.
    """
    UV = np.asarray(UV, dtype=np.float64)
    if not (np.isfinite(mm_per_unit) and mm_per_unit > 0):
        raise BolusError(f"the scene's unit scale must be a length > 0, got {mm_per_unit} mm per unit")
    if UV.ndim != 2 or UV.shape[1] != 2 or not np.isfinite(UV).all():
        raise BolusError(f"pattern positions must be a finite (n, 2) array, got shape {UV.shape}")
    co = np.zeros((len(UV), 3), dtype=np.float32)
    co[:, :2] = UV / mm_per_unit
    return co, co[:, :2].astype(np.float64) * mm_per_unit


@dataclass
class PatternBuild:
    """Everything the pattern object is made of.

    co (N,3) float32 scene units; polygons (`PatternPolygons`); poly_patch (p,) patch of
    every polygon; poly_piece (p,) piece (island) of every polygon; area_error (p,) A / A0 - 1
    of every polygon; errors {piece: (EL, EA, flipped)} and None for all; UV (N,2) mm as
    stored; vert_source (N,) the region vertex (row of V) of every pattern vertex; rows: the
    pattern table (`piece_rows`).
    """

    co: np.ndarray
    polygons: PatternPolygons
    poly_patch: np.ndarray
    area_error: np.ndarray
    errors: dict
    UV: np.ndarray
    rows: list = field(default_factory=list)
    poly_piece: np.ndarray | None = None
    vert_source: np.ndarray | None = None


def build_pattern(V, F, tri_poly, vert_ids, islands: PatchIslands, unfoldings: list, poly_labels,
                  loop_start, loop_total, loop_vert, mm_per_unit: float, gap_mm: float) -> PatternBuild:
    """Lay the unfolded islands out (`assemble.assemble_pattern`) and measure them as SPEC does.

    Parameters
    ----------
    V : (n,3) mm, F : (m,3) - the region (or its mid-surface: the reference EL / EA are
        measured against); tri_poly (m,), vert_ids (n,) as in `pattern_polygons`
    islands : the pieces (`patch_islands` of the region, or `collect_pieces` after darts and
        splits); unfoldings : one `Unfolding` per island, in order
    poly_labels : (P,) int - the patch of every mesh polygon
    loop_start, loop_total, loop_vert : the mesh's polygons (see `pattern_polygons`)
    mm_per_unit : mm in one scene unit; gap_mm : space between islands

    Returns
    -------
    PatternBuild; EL / EA (eqs. 3-30, 3-31) of each piece and of all are measured on the
    stored (float32) positions against the source polygons.
    """
    if len(unfoldings) != islands.count:
        raise BolusError(f"internal error: {len(unfoldings)} unfoldings for {islands.count} islands")
    pattern = assemble_pattern(F, islands.islands, unfoldings, gap_mm=gap_mm)
    polys = pattern_polygons(tri_poly, islands.islands, F, pattern.F, vert_ids, loop_start, loop_total, loop_vert)
    co, UV = stored_positions(pattern.UV, mm_per_unit)
    poly_patch = np.asarray(poly_labels, dtype=np.int64)[polys.polys]
    tri_poly = np.asarray(tri_poly, dtype=np.int64)
    inside = islands.islands >= 0
    piece_of_poly = np.full(int(tri_poly.max()) + 1 if len(tri_poly) else 0, -1, dtype=np.int64)
    piece_of_poly[tri_poly[inside]] = islands.islands[inside]
    poly_piece = piece_of_poly[polys.polys]
    args = (np.asarray(V, dtype=np.float64), polys.corner_src, UV, polys.corner_pat, polys.sizes)
    errors = polygon_errors(*args, groups=poly_piece)
    build = PatternBuild(co, polys, poly_patch, polygon_area_error(*args), errors, UV, poly_piece=poly_piece,
                         vert_source=np.asarray(pattern.vert_source, dtype=np.int64))
    build.rows = piece_rows(islands, unfoldings, errors)
    return build


def piece_rows(islands: PatchIslands, unfoldings: list, errors: dict) -> list[dict]:
    """The pattern table: one row per island (piece) with its EL / EA / flips from ``errors``
    ({island: (EL, EA, flipped)}) when measured there, else the unfolding's own; named
    "patch p" or "patch p piece i/k" (``piece_in_patch`` i, 1-based, ``pieces_in_patch`` k)."""
    pieces_of = np.bincount(islands.island_patch[islands.island_patch >= 0])
    faces = np.bincount(islands.islands[islands.islands >= 0], minlength=islands.count)
    seen: dict[int, int] = {}
    rows = []
    for k, u in enumerate(unfoldings):
        p = int(islands.island_patch[k])
        seen[p] = seen.get(p, 0) + 1
        el, ea, fl = errors.get(k, (u.EL, u.EA, u.flipped))
        rows.append({"island": k, "patch": p, "piece_in_patch": seen[p], "pieces_in_patch": int(pieces_of[p]),
                     "faces": int(faces[k]), "EL": el, "EA": ea, "flipped": fl,
                     "overlaps": u.overlaps, "cut": u.cut, "seconds": round(u.seconds, 3),
                     "iterations": u.iterations, "method": u.method,
                     "name": f"patch {p}" + (f" piece {seen[p]}/{pieces_of[p]}" if pieces_of[p] > 1 else "")})
    return rows


def diagnose_pieces(V, F, islands: PatchIslands, unfoldings: list, rows: list[dict],
                    warn_fraction: float = DEFAULT_WARN_FRACTION,
                    sigma_mm: float = DEFAULT_SMOOTHING_MM) -> None:
    """Add to every row its pattern/skin area ratio, its angle excess / deficit, ``warn``
    and the advice of `piece_advice` (EL or EA above ``warn_fraction``, flips or overlaps
    make a piece not to cut as it is).  V (n,3) mm, F (m,3) the region, as given to
    `patch_islands`.  A piece `piece_advice` cannot diagnose still gets ``warn`` from its
    figures and "(no diagnosis: ...)" as advice."""
    V = np.asarray(V, dtype=np.float64)
    for k, (u, row) in enumerate(zip(unfoldings, rows)):
        skin = float(face_areas(V[u.vert_origin], u.F).sum())
        row["area_ratio"] = float(signed_areas(u.UV, u.F).sum()) / skin if skin > 0 else 0.0
        Fk, used = submesh(F, islands.islands == k)
        bad = bool(row["EL"] > warn_fraction or row["EA"] > warn_fraction or row["flipped"] or row["overlaps"])
        try:
            adv = piece_advice(V[used], Fk, row["EL"], row["EA"], row["flipped"], row["overlaps"],
                               threshold=warn_fraction, sigma_mm=sigma_mm)
        except BolusError as exc:  # the figures are still worth a warning
            row.update(kind="", excess_rad=None, deficit_rad=None, advice=f"(no diagnosis: {exc})",
                       short_advice="", warn=bad)
            continue
        row.update(kind=adv.kind, excess_rad=adv.excess_rad, deficit_rad=adv.deficit_rad, advice=adv.advice,
                   short_advice=adv.short_advice, warn=adv.distorted)


def piece_warning(row: dict, warn_pct: float) -> str:
    """The WARNING for a piece not to cut as it is: its figures and the advice."""
    return (f"{row['name'].capitalize()}: EL {row['EL'] * 100:.1f} %, EA {row['EA'] * 100:.1f} %, pattern area "
            f"{row['area_ratio']:.2f} of the skin, {row['flipped']} flipped and {row['overlaps']} overlapping "
            f"triangles: above the {warn_pct:g} % limit, do not cut it as it is; {row['advice']}")


def pattern_messages(unfoldings: list, rows: list[dict], errors: dict, warn_pct: float,
                     name: str) -> list[tuple[str, str]]:
    """The report of a finished pattern as ``[(level, text)]`` in the order to show them,
    level "WARNING" or "INFO"; ``name`` is the pattern object's.

    Per piece, its unfolding's own `Unfolding.warnings` (the core says there what is wrong
    with the pattern: flips, overlaps, a folded start) and, as INFO, how a piece that was
    not a disk was cut (`Unfolding.cut`); then the totals and one line of figures per
    piece (INFO); then `piece_warning` of every row with ``warn`` and, last (the status
    bar shows the last report), how many pieces are not fit to cut.
    """
    out: list[tuple[str, str]] = []
    for u, row in zip(unfoldings, rows):
        out.extend(("WARNING", f"{row['name']}: {w}") for w in u.warnings)
        if row["cut"]:
            out.append(("INFO", f"{row['name']}: not a disk, {row['cut']}"))
    el, ea, fl = errors[None]
    out.append(("INFO", f"Unfolded {len(rows)} islands into '{name}': EL {el * 100:.2f} %, EA {ea * 100:.2f} %, "
                        f"{fl} flipped faces"))
    out.extend(("INFO", f"{row['name'].capitalize()}: {row['faces']} triangles, EL {row['EL'] * 100:.3f} %, "
                        f"EA {row['EA'] * 100:.3f} %, flipped {row['flipped']}, pattern area "
                        f"{row.get('area_ratio', 0.0):.3f} of the skin, {row['seconds']:.2f} s") for row in rows)
    bad = [row for row in rows if row.get("warn")]
    out.extend(("WARNING", piece_warning(row, warn_pct)) for row in bad)
    if bad:
        out.append(("WARNING", f"{len(bad)} of {len(rows)} pattern pieces are not fit to cut (EL or EA above "
                               f"{warn_pct:g} %, or folded over): " + ", ".join(row["name"] for row in bad)
                    + "; see the advice above"))
    return out


def add_sheet_figures(rows: list[dict], layout: SheetLayout, bending: list | None) -> None:
    """Add to every row its darts, its patch's splits and (with a sheet thickness) the
    bending figures of `mid_surface.piece_bending` (R_min_mm, strain, sheet = "sheet" /
    "print", sheet_reason); without a thickness ``sheet`` comes from the EL target only."""
    for k, row in enumerate(rows):
        row["darts"] = layout.darts_of(k)
        row["splits"] = layout.splits_of(row["patch"])
        if bending is not None:
            b = bending[k]
            R = float(b.R_min_mm)
            row.update(R_min_mm=R if np.isfinite(R) else None, strain=float(b.strain), sheet=b.advice,
                       sheet_reason=b.reason)


def sheet_messages(rows: list[dict], layout: SheetLayout, max_el: float, thickness_mm: float) -> list[tuple[str, str]]:
    """The refinement's and the advice's messages as ``[(level, text)]``: per patch its darts
    and splits (INFO), the patches that miss ``max_el`` (fraction) with the core's reason
    (WARNING), every piece advised "print" with its figures (WARNING) and a count of the
    advice (INFO).  ``thickness_mm`` 0: no bending figures."""
    out: list[tuple[str, str]] = []
    for p in sorted({r["patch"] for r in rows}):
        mine = [r for r in rows if r["patch"] == p]
        darts, splits = sum(r.get("darts", 0) for r in mine), layout.splits_of(p)
        if darts or splits:
            worst = max(mine, key=lambda r: r["EL"])
            out.append(("INFO", f"Patch {p}: {darts} dart{'s' * (darts != 1)} and {splits} split"
                                f"{'s' * (splits != 1)}: {len(mine)} piece{'s' * (len(mine) != 1)}, worst EL "
                                f"{worst['EL'] * 100:.2f} % / EA {worst['EA'] * 100:.2f} % ({worst['name']})"))
    for p, reason in layout.unmet:
        out.append(("WARNING", f"Patch {p} misses the {max_el * 100:g} % EL target: {reason}"))
    advised = [r for r in rows if "sheet" in r]
    for r in advised:
        # a piece already warned for its EL / EA gets this only when its bending is the news
        bends = thickness_mm > 0 and r.get("R_min_mm") is not None and r["R_min_mm"] < SHEET_RADIUS_FACTOR * thickness_mm
        if r["sheet"] == "print" and (bends or not r.get("warn")):
            reason = r.get("sheet_reason") or "use the printed bolus"
            out.append(("WARNING", f"{r['name'].capitalize()}: {reason[0].upper()}{reason[1:]} (EL "
                                   f"{r['EL'] * 100:.1f} %, EA {r['EA'] * 100:.1f} %)"))
    if advised:
        n_print = sum(r["sheet"] == "print" for r in advised)
        out.append(("INFO", f"Sheet or print: {len(advised) - n_print} piece{'s' * (len(advised) - n_print != 1)} "
                            f"can be cut from a {thickness_mm:g} mm sheet, {n_print} should be printed"
                    if thickness_mm > 0 else
                    f"Sheet or print: {len(advised) - n_print} of {len(advised)} pieces meet the EL target "
                    "(give a sheet thickness for the bending advice)"))
    return out


def table_rows(text: str | None) -> dict[int, dict]:
    """The pattern table's rows (JSON text of the pattern object) by patch, first row of each;
    {} when there is none or it cannot be read (the SVG then has no figures)."""
    if not text:
        return {}
    try:
        table = {}
        for r in json.loads(text)["islands"]:
            table.setdefault(int(r["patch"]), r)
        return table
    except (ValueError, KeyError, TypeError):
        return {}


def svg_pieces(P, F, tri_poly, poly_patch, table: dict | None = None) -> list[dict]:
    """The pattern's pieces for `pattern_svg`: one per patch, in increasing patch order.

    Parameters
    ----------
    P : (n,2) mm - pattern positions (as laid out); F : (t,3) its triangles
    tri_poly : (t,) polygon of every triangle; poly_patch : (p,) patch of every polygon
    table : {patch: row} of `table_rows`, for the EL / EA printed on each piece

    Returns
    -------
    [{"UV" (k,2), "F" (j,3), "label" "Patch p", "EL", "EA"}] (EL / EA None when unknown).
    """
    rows = [dict(r, island=int(p), name=f"patch {int(p)}") for p, r in (table or {}).items()]
    return [{"UV": q["UV"], "F": q["F"], "label": q["label"], "EL": q["EL"], "EA": q["EA"]}
            for q in export_pieces(P, F, tri_poly, poly_patch, poly_patch, rows)]


def export_pieces(P, F, tri_poly, poly_piece, poly_patch, rows: list[dict] | None = None) -> list[dict]:
    """The pattern's pieces for `pattern_export.write_pattern`: one per piece, in piece order.

    Parameters
    ----------
    P : (n,2) mm - pattern positions as laid out; F : (t,3) its triangles (rows of P)
    tri_poly : (t,) polygon of every triangle; poly_piece, poly_patch : (p,) piece / patch of
        every polygon (an old pattern without pieces: pass the patches as the pieces)
    rows : the pattern table's rows (``bolus_pattern_table`` "islands", indexed by piece),
        for the name "patch p piece i/k" and the EL / EA printed on each piece

    Returns
    -------
    [{"UV" (k,2), "F" (j,3), "verts" (k,) rows of P, "piece", "patch", "label" ("Patch 0
    piece 1/2"), "EL", "EA"}] (EL / EA None when unknown).
    """
    P = np.asarray(P, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] < 2:
        raise BolusError(f"pattern positions must be an (n, 2) array, got shape {P.shape}")
    P, F = as_pattern_arrays(P[:, :2], F)
    tri_poly = np.asarray(tri_poly, dtype=np.int64)
    poly_piece = np.asarray(poly_piece, dtype=np.int64)
    poly_patch = np.asarray(poly_patch, dtype=np.int64)
    if poly_piece.shape != poly_patch.shape:
        raise BolusError(f"{len(poly_piece)} piece labels for {len(poly_patch)} polygons")
    if tri_poly.shape != (len(F),) or (len(F) and (tri_poly.min() < 0 or tri_poly.max() >= len(poly_piece))):
        raise BolusError(f"the pattern needs one polygon per triangle ({len(F)}) among its {len(poly_piece)} "
                         f"polygons, got {tri_poly.shape[0]} values")
    by_piece = {int(r.get("island", i)): r for i, r in enumerate(rows or [])}
    tri_piece = poly_piece[tri_poly]
    pieces = []
    for k in np.unique(tri_piece):
        Fk, verts = submesh(F, tri_piece == k)
        patch = int(np.bincount(poly_patch[tri_poly[tri_piece == k]] - poly_patch.min()).argmax() + poly_patch.min())
        row = by_piece.get(int(k), {})
        name = row.get("name", f"patch {patch}" if k == patch else f"patch {patch} piece {int(k)}")
        pieces.append({"UV": P[verts], "F": Fk, "verts": verts, "piece": int(k), "patch": patch,
                       "label": name[0].upper() + name[1:], "EL": row.get("EL"), "EA": row.get("EA")})
    return pieces
