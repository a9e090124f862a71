"""fmaps: non-rigid 3D shape matching with functional maps, in Rust.

Two surfaces in, a correspondence out::

    import fmaps
    a = fmaps.Mesh.load("tr_reg_080.off")
    b = fmaps.Mesh.load("tr_reg_081.off")
    r = fmaps.match_shapes(a, b)          # the pipeline of `fmaps match`
    r.map_ab                              # for each vertex of A, a vertex of B

Directions are explicit: ``map_ab[i]`` is the vertex of B that vertex ``i``
of A goes to (0-based); ``c_ba`` maps coefficients on B to coefficients
on A. Long calls release the GIL and run on ``threads`` threads (default:
one per core). Errors raise :class:`FmapsError` (a ``ValueError``) with
the message the ``fmaps`` command prints.

A shape's eigenbasis can be computed once (:func:`prepare`) and matched
against many (:func:`match_prepared`); :mod:`fmaps.distributed` does that
for whole collections on a Ray cluster.

The stages one by one, on prepared shapes (pyFM's preprocess / fit /
get_p2p / icp_refine / zoomout_refine): :func:`descriptors`, :func:`fit`
(also on your own per-vertex features), :func:`fmap_to_map`,
:func:`map_to_fmap`, :func:`refine` (every refiner, from any map), and
:func:`geodesics` (exact, heat or Dijkstra).
"""

from ._fmaps import (
    FmapsError,
    MatchResult,
    Mesh,
    PreparedShape,
    RefinedMap,
    __version__,
    demo_pairs,
    descriptors,
    evaluate,
    fit,
    fmap_to_map,
    generated_body,
    geodesics,
    map_quality,
    map_to_fmap,
    match_prepared,
    match_shapes,
    prepare,
    read_indices,
    refine,
    render_transfer,
    spectrum,
    train,
    viewer_html,
)

__all__ = [
    "FmapsError",
    "MatchResult",
    "Mesh",
    "PreparedShape",
    "RefinedMap",
    "__version__",
    "demo_pairs",
    "descriptors",
    "evaluate",
    "fit",
    "fmap_to_map",
    "generated_body",
    "geodesics",
    "map_quality",
    "map_to_fmap",
    "match_prepared",
    "match_shapes",
    "prepare",
    "read_indices",
    "refine",
    "render_transfer",
    "spectrum",
    "train",
    "viewer_html",
]
