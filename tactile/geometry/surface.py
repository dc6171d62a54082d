"""Surface mesh through a taxel cloud: local tangent-plane Delaunay with manifold selection.

Every taxel projects its nearest neighbours onto its tangent plane and keeps the 2D Delaunay
triangles incident to it (its *umbrella*). A candidate triangle is voted by every umbrella that
holds it; candidates are then accepted best first (votes, then shortness) while the mesh stays
a consistently oriented 2-manifold: an edge holds at most two faces, a directed edge at most one,
and the angular wedges of the faces around a taxel (in its tangent plane) never overlap.
Triangles much longer than the local taxel spacing are rejected, so unsensorized regions stay
holes while the small gaps between skin modules are bridged. Slivers (area below
``MIN_AREA_FACTOR`` × spacing², from collinear pads such as the rows of iCub modules on a flat
face) are never candidates, so the selection fills their place with proper triangles.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import breadth_first_order, connected_components, minimum_spanning_tree
from scipy.spatial import Delaunay, QhullError, cKDTree

from tactile.errors import MapError
from tactile.geometry.seams import face_components

N_NEIGHBOURS = 12  # umbrella size: about two rings of a hexagonal lattice
N_SPACING = 3  # nearest neighbours whose median distance is the local spacing
WEDGE_TOL_RAD = 1e-6  # wedges touching along a shared edge do not overlap
MIN_AREA_FACTOR = 1e-4  # triangles of area < this × spacing² are slivers (collinear taxels)


@dataclass(frozen=True)
class SurfaceMesh:
    """Triangles over a taxel cloud.

    faces : (M, 3) int64 taxel indices, counter-clockwise seen from outside (outward normals)
    spacing_m : (N,) float64, m — local spacing (median distance to the 3 nearest taxels)
    n_rejected_long : candidate triangles rejected as longer than ``max_edge_factor`` × spacing
    isolated : (K,) int64 taxels in no triangle
    """

    faces: np.ndarray
    spacing_m: np.ndarray
    n_rejected_long: int
    isolated: np.ndarray


def triangulate(
    positions_m: np.ndarray, normals: np.ndarray | None = None, *, max_edge_factor: float = 2.5
) -> SurfaceMesh:
    """Triangulate a taxel cloud into an oriented manifold surface mesh.

    positions_m : (N, 3) float, m. normals : (N, 3) float, outward, or None. The surface normals
    are always estimated by PCA of the neighbourhoods (some calibration files, e.g. the iCub
    ``left_arm``, hold normals up to 89° off the module planes); given normals only decide which
    side is outward.
    max_edge_factor : a triangle whose longest edge exceeds this × the median local spacing of its
    taxels is rejected (leaves a hole rather than bridging an unsensorized region). Triangles of
    area below ``MIN_AREA_FACTOR`` × that spacing² (collinear taxels) are never emitted.
    """
    p = _check_positions(positions_m)
    k = min(N_NEIGHBOURS, len(p))
    dist, nbr = cKDTree(p).query(p, k)
    spacing = np.median(dist[:, 1 : 1 + N_SPACING], axis=1)
    hint = None if normals is None else _check_normals(normals, len(p))
    n = estimate_normals(p, nbr, hint)
    cand, votes = _umbrella_candidates(p, n, nbr)
    local = np.median(spacing[cand], axis=1)
    longest = _longest_edge(p, cand)
    too_long = longest > max_edge_factor * local
    sliver = _areas(p, cand) < MIN_AREA_FACTOR * local**2
    ok = ~too_long & ~sliver
    cand, votes, longest, local = cand[ok], votes[ok], longest[ok], local[ok]
    cand = _orient(p, n, cand)
    order = np.lexsort((longest / local, -votes))
    faces = _drop_redundant_patches(_select_manifold(p, n, cand[order]))
    used = np.zeros(len(p), bool)
    used[faces.ravel()] = True
    return SurfaceMesh(faces, spacing, int(too_long.sum()), np.flatnonzero(~used).astype(np.int64))


def _check_positions(positions_m: np.ndarray) -> np.ndarray:
    p = np.asarray(positions_m, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or len(p) < 3:
        raise MapError(f"positions_m must be (N >= 3, 3) metres, got shape {p.shape}")
    if not np.isfinite(p).all():
        raise MapError("positions_m holds NaN/inf; drop those taxels first (layout.subset)")
    return p


def _check_normals(normals: np.ndarray, n_taxels: int) -> np.ndarray:
    n = np.asarray(normals, dtype=np.float64)
    if n.shape != (n_taxels, 3) or not np.isfinite(n).all():
        raise MapError(f"normals must be finite ({n_taxels}, 3), got shape {n.shape}")
    length = np.linalg.norm(n, axis=1, keepdims=True)
    if (length < 1e-12).any():
        raise MapError("normals has zero rows; pass normals=None to estimate them")
    return n / length


def estimate_normals(p: np.ndarray, nbr: np.ndarray, hint: np.ndarray | None = None) -> np.ndarray:
    """PCA normals (N, 3) of each neighbourhood, consistently oriented outward.

    p : (N, 3) float, m. nbr : (N, k) int neighbour indices (self first). hint : (N, 3) given
    normals or None. Orientation is propagated over the minimum spanning tree of the neighbour
    graph weighted by 1 - |n_i . n_j| (Hoppe et al. 1992); each connected part is then signed
    by the given normals when they agree clearly, else to point away from the centroid.
    """
    local = p[nbr] - p[nbr].mean(axis=1, keepdims=True)
    n = np.linalg.svd(local, full_matrices=False)[2][:, 2, :].copy()
    rows = np.repeat(np.arange(len(p)), nbr.shape[1] - 1)
    cols = nbr[:, 1:].ravel()
    weight = 1.0 - np.abs(np.einsum("ij,ij->i", n[rows], n[cols])) + 1e-9
    tree = minimum_spanning_tree(coo_matrix((weight, (rows, cols)), shape=(len(p),) * 2))
    _, label = connected_components(tree, directed=False)
    for comp in np.unique(label):
        root = int(np.flatnonzero(label == comp)[0])
        order, parent = breadth_first_order(tree, root, directed=False)
        for v in order[1:]:
            if n[v] @ n[parent[v]] < 0:
                n[v] = -n[v]
        n[order] *= _outward_sign(p, n, order, hint)
    return n


def _outward_sign(
    p: np.ndarray, n: np.ndarray, members: np.ndarray, hint: np.ndarray | None
) -> float:
    """+1 or -1 so that normals n[members] point outward (given normals first, else centroid)."""
    if hint is not None:
        dot = np.einsum("ij,ij->i", n[members], hint[members])
        if abs(dot.sum()) > 0.5 * np.abs(dot).sum():
            return float(np.sign(dot.sum()))
    away = np.einsum("ij,ij->i", n[members], p[members] - p.mean(axis=0))
    return 1.0 if away.sum() >= 0 else -1.0


def _umbrella_candidates(
    p: np.ndarray, n: np.ndarray, nbr: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Candidate triangles (C, 3) int (sorted rows) and their votes (C,) int."""
    tris = []
    for i in range(len(p)):
        ring = nbr[i][n[nbr[i]] @ n[i] > 0.0]  # no taxels of a facing surface
        if len(ring) < 3:
            continue
        e1, e2 = _tangent_basis(n[i])
        local = (p[ring] - p[i]) @ np.column_stack([e1, e2])
        try:
            simplices = Delaunay(local).simplices
        except QhullError:
            continue
        tris.append(ring[simplices[(simplices == 0).any(axis=1)]])
    if not tris:
        raise MapError("no triangle could be formed: are the taxels all collinear?")
    cand, votes = np.unique(np.sort(np.concatenate(tris), axis=1), axis=0, return_counts=True)
    return cand.astype(np.int64), votes


def _tangent_basis(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors (3,) spanning the plane orthogonal to ``normal`` (right-handed)."""
    helper = np.eye(3)[np.argmin(np.abs(normal))]
    e1 = np.cross(normal, helper)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(normal, e1)


def _longest_edge(p: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Longest edge length (T,) of triangles tri (T, 3)."""
    a, b, c = p[tri[:, 0]], p[tri[:, 1]], p[tri[:, 2]]
    lengths = np.linalg.norm(np.stack([b - a, c - b, a - c]), axis=2)
    return lengths.max(axis=0)


def _areas(p: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Areas (T,) of triangles tri (T, 3), in the units of p squared."""
    a, b, c = p[tri[:, 0]], p[tri[:, 1]], p[tri[:, 2]]
    return 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)


def _orient(p: np.ndarray, n: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Reorder triangles (T, 3) so their normal agrees with the mean taxel normal."""
    a, b, c = p[tri[:, 0]], p[tri[:, 1]], p[tri[:, 2]]
    flip = np.einsum("ij,ij->i", np.cross(b - a, c - a), n[tri].sum(axis=1)) < 0
    out = tri.copy()
    out[flip, 1], out[flip, 2] = tri[flip, 2], tri[flip, 1]
    return out


def _select_manifold(p: np.ndarray, n: np.ndarray, cand: np.ndarray) -> np.ndarray:
    """Accept oriented candidates (C, 3) in order while the mesh stays an oriented manifold.

    Returns faces (M, 3) int64. A triangle is accepted when none of its directed edges is used,
    none of its undirected edges already has two faces, and its wedge at each corner (an arc of
    directions in that taxel's tangent plane) overlaps no wedge accepted there.
    """
    wedges = _corner_wedges(p, n, cand)
    directed: set[tuple[int, int]] = set()
    undirected: dict[tuple[int, int], int] = {}
    arcs: dict[int, list[tuple[float, float]]] = {}
    keep = []
    for t, tri in enumerate(cand.tolist()):
        edges = [(tri[0], tri[1]), (tri[1], tri[2]), (tri[2], tri[0])]
        if any(e in directed or undirected.get(_key(e), 0) >= 2 for e in edges):
            continue
        corner = wedges[t]
        if not all(_arc_free(arcs.get(v, []), *corner[j]) for j, v in enumerate(tri)):
            continue
        keep.append(t)
        for e in edges:
            directed.add(e)
            undirected[_key(e)] = undirected.get(_key(e), 0) + 1
        for j, v in enumerate(tri):
            arcs.setdefault(v, []).append(tuple(corner[j]))
    return cand[keep].reshape(-1, 3).astype(np.int64)


def _key(edge: tuple[int, int]) -> tuple[int, int]:
    return (edge[0], edge[1]) if edge[0] < edge[1] else (edge[1], edge[0])


def _corner_wedges(p: np.ndarray, n: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Wedge (start angle, span) in rad of every corner, in the corner taxel's tangent plane.

    tri : (T, 3) oriented triangles. Returns (T, 3, 2); a span >= pi (corner seen folded in
    the tangent plane) is set to 2 pi so that the triangle is never accepted.
    """
    out = np.empty((len(tri), 3, 2))
    for j in range(3):
        v, a, b = tri[:, j], tri[:, (j + 1) % 3], tri[:, (j + 2) % 3]
        e1 = np.cross(n[v], np.eye(3)[np.argmin(np.abs(n[v]), axis=1)])
        e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
        e2 = np.cross(n[v], e1)
        da, db = p[a] - p[v], p[b] - p[v]
        ang_a = np.arctan2(np.einsum("ij,ij->i", da, e2), np.einsum("ij,ij->i", da, e1))
        ang_b = np.arctan2(np.einsum("ij,ij->i", db, e2), np.einsum("ij,ij->i", db, e1))
        span = np.mod(ang_b - ang_a, 2 * np.pi)
        out[:, j, 0], out[:, j, 1] = ang_a, np.where(span >= np.pi, 2 * np.pi, span)
    return out


def _arc_free(arcs: list[tuple[float, float]], start: float, span: float) -> bool:
    """True when the arc [start, start + span] overlaps none of ``arcs`` (except at ends)."""
    for s, w in arcs:
        d = (start - s) % (2 * np.pi)
        if d < w - WEDGE_TOL_RAD or d > 2 * np.pi - span + WEDGE_TOL_RAD:
            return False
    return True


def _drop_redundant_patches(faces: np.ndarray) -> np.ndarray:
    """Drop edge-connected face groups (smallest first) that add no taxel to the others.

    Such groups hang on the mesh by single vertices (a triangle half across a gap).
    """
    if len(faces) == 0:
        return faces
    label = face_components(faces)
    sizes = np.bincount(label)
    count = np.bincount(faces.ravel(), minlength=faces.max() + 1)
    keep = np.ones(len(faces), bool)
    for comp in np.argsort(sizes, kind="stable"):
        mine = label == comp
        own = np.bincount(faces[mine].ravel(), minlength=len(count))
        if np.all(count[faces[mine].ravel()] > own[faces[mine].ravel()]):
            keep[mine] = False
            count -= own
    return faces[keep]
