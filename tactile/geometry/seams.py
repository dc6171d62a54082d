"""Mesh topology for flattening: corner-based vertex splitting, patches, seams between boundaries.

A flat map needs a disk-like patch. `split_vertices` gives every edge-connected fan of faces
around a vertex its own vertex, which both separates non-manifold vertices (two fans touching at
one taxel) and opens seams (cut edges); `seam_edges` finds the shortest cut between two
boundary loops, which turns a tube (annulus) into a strip.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components, dijkstra


def split_vertices(
    faces: np.ndarray, cut_edges: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """One vertex per edge-connected fan of corners around each vertex.

    faces : (M, 3) int, consistently oriented. cut_edges : (C, 2) int vertex pairs not to be
    crossed (seams). Returns new faces (M, 3) int64 and vertex_orig (V', ) int64, the original
    vertex of each new vertex.
    """
    pairs = _shared_edge_pairs(faces, cut_edges)
    n_corners = faces.size
    rows, cols = [], []
    for end in (0, 1):
        rows.append(3 * pairs[:, 0] + pairs[:, 2 + end])
        cols.append(3 * pairs[:, 1] + pairs[:, 4 + end])
    graph = coo_matrix(
        (np.ones(2 * len(pairs)), (np.concatenate(rows), np.concatenate(cols))),
        shape=(n_corners, n_corners),
    )
    _, label = connected_components(graph, directed=False)
    _, first, new_label = np.unique(label, return_index=True, return_inverse=True)
    order = np.argsort(first)  # number new vertices by first corner: deterministic
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    new_faces = rank[new_label].reshape(faces.shape).astype(np.int64)
    vertex_orig = np.empty(len(order), np.int64)
    vertex_orig[new_faces.ravel()] = faces.ravel()
    return new_faces, vertex_orig


def _shared_edge_pairs(faces: np.ndarray, cut_edges: np.ndarray | None) -> np.ndarray:
    """Rows (f1, f2, j1a, j1b, j2a, j2b) for every edge shared by exactly two faces, not cut.

    j1a/j2a are the corners of the edge's first endpoint in f1/f2, j1b/j2b of the second.
    """
    m = len(faces)
    f = np.tile(np.arange(m), 3)
    j = np.repeat(np.arange(3), m)
    a, b = faces[f, j], faces[f, (j + 1) % 3]
    key = np.minimum(a, b) * (faces.max() + 1) + np.maximum(a, b)
    order = np.lexsort((f, key))
    key, f, j, a = key[order], f[order], j[order], a[order]
    _, start, count = np.unique(key, return_index=True, return_counts=True)
    start = start[count == 2]
    if cut_edges is not None and len(cut_edges):
        cut = np.sort(np.asarray(cut_edges), axis=1)
        cut_key = cut[:, 0] * (faces.max() + 1) + cut[:, 1]
        start = start[~np.isin(key[start], cut_key)]
    h1, h2 = start, start + 1
    same = a[h1] == a[h2]  # same direction: inconsistent orientation, still glue by vertex
    j1a, j1b = j[h1], (j[h1] + 1) % 3
    j2a = np.where(same, j[h2], (j[h2] + 1) % 3)
    j2b = np.where(same, (j[h2] + 1) % 3, j[h2])
    return np.column_stack([f[h1], f[h2], j1a, j1b, j2a, j2b])


def face_components(faces: np.ndarray) -> np.ndarray:
    """Label (M,) int64 of the edge-connected component of each face."""
    pairs = _shared_edge_pairs(faces, None)
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(faces),) * 2)
    return connected_components(graph, directed=False)[1].astype(np.int64)


def boundary_loops(faces: np.ndarray) -> list[np.ndarray]:
    """Boundary loops of a manifold mesh as vertex arrays, longest (most vertices) first."""
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    key = np.sort(e, axis=1)
    _, inv, count = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    border = e[count[inv.ravel()] == 1]
    succ = dict(zip(border[:, 0].tolist(), border[:, 1].tolist(), strict=True))
    loops, seen = [], set()
    for start in sorted(succ):
        if start in seen:
            continue
        loop, v = [], start
        while v not in seen and v in succ:
            seen.add(v)
            loop.append(v)
            v = succ[v]
        loops.append(np.array(loop, np.int64))
    return sorted(loops, key=lambda lp: (-len(lp), int(lp.min())))


def seam_edges(
    xyz: np.ndarray, faces: np.ndarray, loop_a: np.ndarray, loop_b: np.ndarray
) -> np.ndarray:
    """Interior edges (C, 2) of the shortest path (3D length) from loop_a to loop_b.

    xyz : (V, 3) float vertex positions. Returns an empty (0, 2) array when no path exists.
    """
    e = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    edges, count = np.unique(e, axis=0, return_counts=True)
    interior = edges[count == 2]
    length = np.linalg.norm(xyz[interior[:, 0]] - xyz[interior[:, 1]], axis=1)
    graph = coo_matrix((length, (interior[:, 0], interior[:, 1])), shape=(len(xyz),) * 2)
    dist, pred, _ = dijkstra(
        graph, directed=False, indices=loop_a, min_only=True, return_predecessors=True
    )
    end = loop_b[np.argmin(dist[loop_b])]
    if not np.isfinite(dist[end]):
        return np.zeros((0, 2), np.int64)
    path = [end]
    while pred[path[-1]] >= 0:
        path.append(pred[path[-1]])
    return np.column_stack([path[:-1], path[1:]]).astype(np.int64)
