"""The rough-diffuse reflectance model of Oren & Nayar (1995) at every level of the paper.

Modules
-------
vcavity
    One V-cavity: projected radiance of a tilted Lambertian facet (eq 10), the geometric
    attenuation factor (eq 14-16, Table 1), two-bounce interreflection (eq 17-25).
single_slope
    Surfaces made of V-cavities of one slope: uni-directional (eq 28) and isotropic
    (Appendix A, eq 39-49).
exact
    ``oren-nayar-numerical`` (eq 31-32 as the paper evaluated it) and
    ``oren-nayar-exact`` (the V-cavity model integrated over facet normals, the reference).
functional
    the formulas of ``oren-nayar`` (functional approximation, eq 33-35) and
    ``oren-nayar-qualitative`` (eq 36).
compiled
    their compiled plain calls (numba).
registered
    the two registered models, joining both.

References
----------
M. Oren, S. K. Nayar, "Generalization of the Lambertian model and implications for machine
vision", IJCV 14(3), 1995 (tech. report CUCS-057-92, rev. 1996).
"""
