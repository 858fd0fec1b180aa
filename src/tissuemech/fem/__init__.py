"""Real-time finite elements: TLED (total Lagrangian explicit dynamics) on linear tetrahedra.

Modules
-------
mesh        structured block / rheometer-cylinder meshes, 1:8 refinement, quality, meshio I/O, MNI brain mesh (optional)
materials   3-D hyperelastic stress (same scalar laws as the fits), nearly incompressible split, QLV
tled        numba CPU solver: explicit central difference, dynamic relaxation, ANP, BCs, rigid contact
cuda        optional numba-cuda solver: explicit steps and dynamic relaxation (persistent cooperative kernels)
experiments virtual rheometer torsion and flat-punch indentation -> canonical datasets + VTU
"""
