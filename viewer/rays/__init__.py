"""Rays through a scene: the voxels and the compiled ray kernels every stage casts with.

    voxels.py       Scene -> VoxelGrid (occupied voxels, fine light samples)
    pieces.py       each triangle's pieces binned per voxel as they are made (compiled)
    voxel_faces.py  which faces land in which voxel (FaceVoxels), for incremental re-voxelizing
    listing.py      which triangles reach into which cells of a grid; a move's moved faces merged into it
    moved_faces.py  which faces moved between two versions of a scene, and the box around them
    dda.py          cell-exact DDA against the triangles (numba): the exact ray caster, per voxel or face
    cast.py         closest hits (face, distance, barycentrics, side) of many rays: Embree, or the DDA without it
    embree.py       Embree called from compiled loops, on every core and without Python's lock; the order
                    parallel loops take their items in, so that the cores' shares cost alike (`spread`)
    packets.py      Embree's eight-ray packet queries from compiled loops (nearly parallel rays together)
    voxel_rays.py   rays that land on the voxel of the surface they meet (the solver's, the neural source's)
    raymarch.py     distance-field marching through the voxel occupancy (the paper kernel's visibility)
"""
