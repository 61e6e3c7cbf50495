"""Thoroughly pitted surfaces: Koenderink, van Doorn, Dana & Nayar (1999).

Modules
-------
interreflection
    Closed-form interreflection inside a spherical pit (eq 3-13).
cavity
    Geometry of one pit: the point seen through the orifice, cast shadow (section 4.1).
closed_form
    The single-scattering integral for any aperture (eq 14-15) in closed form, compiled:
    what the registered model evaluates.
quadrature
    The same integral by deterministic quadrature: the reference for the closed form,
    used by the model at horizon slivers.
hemispherical
    The hemispherical pit: eq 21-25 (1-D integral) and eq 26-31 (plane of incidence).
shallow
    Monte Carlo estimate for any aperture (section 4.1) with standard error and seed.
textons
    Textons, radiance histograms and tiled textures (section 4.2, Figs 13-14).
model
    The registered ``pitted`` model and aperture distributions (section 5).

References
----------
J. J. Koenderink, A. J. van Doorn, K. J. Dana, S. K. Nayar, "Bidirectional reflection
distribution function of thoroughly pitted surfaces", IJCV 31(2/3), 1999.
"""
