"""Rays through a scene: the voxels and the compiled ray kernels every stage casts with.

    voxels.py       Scene -> VoxelGrid (occupied voxels, fine light samples)
    voxel_faces.py  which faces land in which voxel (FaceVoxels), for incremental re-voxelizing
    dda.py          cell-exact DDA against the triangles (numba): the exact ray caster, per voxel or face
    cast.py         closest hits (face, distance, barycentrics, side) of many rays: Embree, or the DDA without it
    raymarch.py     distance-field marching through the voxel occupancy (the paper kernel's visibility)
"""
