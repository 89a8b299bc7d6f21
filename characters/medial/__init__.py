"""Builders and kernels behind `characters.medial.MedialObject`.

- `mesh_input`: load, repair and check the closed surface;
- `skeleton`: Voronoi-based skeletonisation (pure array functions, numba ray casting);
- `joints`: joint cuts, the section tree and the per-step pose kernels;
- `constraints`: spring reduction on the bone springs, per mass point;
- `creature`: the shipped caterpillar asset, built procedurally;
- `preview`: matplotlib pictures of meshes (quick looks).
"""
