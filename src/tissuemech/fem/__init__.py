"""Real-time finite elements: TLED (total Lagrangian explicit dynamics) on linear tetrahedra.

Modules
-------
mesh        structured block / rheometer-cylinder meshes, quality, meshio I/O, MNI brain mesh (optional)
materials   3-D hyperelastic stress (same scalar laws as the fits), nearly incompressible split, QLV
tled        numba CPU solver: explicit central difference, dynamic relaxation, ANP, BCs, rigid contact
cuda        optional numba-cuda persistent kernel (explicit steps)
experiments virtual rheometer torsion and flat-punch indentation -> canonical datasets + VTU
"""
