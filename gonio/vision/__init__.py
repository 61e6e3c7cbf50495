"""What a camera sees of a reflectance model (Oren & Nayar 1995, section 6, "Implications
for machine vision"): rendered shapes and reflectance maps (:mod:`gonio.vision.shading`)
and photometric stereo under Lambert's and under a rough model
(:mod:`gonio.vision.stereo`). docs/vision.md shows both."""
from .shading import (Brdf, cylinder_normals, direction, gradient_normals, lambert_albedo, lambert_brdf,
                      local_angles, reflectance_map, render, sphere_normals)
from .stereo import StereoResult, angular_error, height_profile, lambertian_stereo, photometric_stereo, summary

__all__ = ["Brdf", "direction", "sphere_normals", "cylinder_normals", "gradient_normals", "local_angles", "render",
           "lambert_brdf", "lambert_albedo", "reflectance_map", "StereoResult", "angular_error", "lambertian_stereo",
           "photometric_stereo", "summary", "height_profile"]
