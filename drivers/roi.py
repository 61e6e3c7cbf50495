"""The radiance window: where the sample is imaged and which pixels measure its radiance.

The sample of side ``s`` seen from polar angle ``theta_r`` is imaged as a rectangle
``s cos(theta_r) m / p`` by ``s m / p`` pixels (far-field magnification ``m = f / D``,
pixel pitch ``p``; docs/protocol.md, "Image geometry"). The region of interest covers the
central ``fraction`` x ``fraction`` of the sample at every camera angle.
"""
from __future__ import annotations

import math

from .camera import Roi, SensorInfo
from .errors import GeometryError

__all__ = ["SAMPLE_SIZE_MM", "sample_image_size", "roi_for_view", "roi_problem"]

#: Side of the square sample (2 inch) [mm].
SAMPLE_SIZE_MM = 50.8


def sample_image_size(info: SensorInfo, view: float, sample_size_mm: float = SAMPLE_SIZE_MM) -> tuple[float, float]:
    """Width (along the swing plane, image x) and height of the sample's image [pixel].

    ``s cos(theta_r) m / p`` by ``s m / p`` with the far-field magnification ``m = f / D``
    and pixel pitch ``p`` (docs/protocol.md, "Image geometry").

    Examples
    --------
    >>> info = SensorInfo(512, 480, 12, 15.0, 150.0, 1828.8)
    >>> [round(v, 1) for v in sample_image_size(info, 60.0)]
    [138.9, 277.8]
    """
    scale = info.focal_length_mm / info.distance_mm / (info.pixel_pitch_um * 1e-3)
    theta_r = abs(float(view))
    return sample_size_mm * math.cos(math.radians(theta_r)) * scale, sample_size_mm * scale


def roi_for_view(
    info: SensorInfo,
    view: float,
    *,
    fraction: float = 0.5,
    sample_size_mm: float = SAMPLE_SIZE_MM,
    margin_px: float = 2.0,
) -> Roi:
    """ROI covering the central ``fraction`` x ``fraction`` of the sample at camera angle ``view``.

    The window is ``fraction * s`` on the sample in both directions; in the image it is
    foreshortened by ``cos(theta_r)`` along x. It is centred on the image centre (where
    the sample centre is imaged), with even pixel sizes.

    Raises
    ------
    GeometryError
        If the ROI would not lie inside the sample's image with ``margin_px`` pixels to
        spare on each side, or would be narrower than 2 pixels (grazing view).
    ValueError
        If ``fraction`` is not in (0, 1].

    Examples
    --------
    >>> info = SensorInfo(512, 480, 12, 15.0, 150.0, 1828.8)
    >>> roi_for_view(info, 0.0)
    Roi(x0=187, y0=171, width=138, height=138)
    """
    if not 0 < fraction <= 1:
        raise ValueError(f"fraction={fraction!r} is invalid; it must be in (0, 1]")
    sample_w, sample_h = sample_image_size(info, view, sample_size_mm)
    # Even sizes keep the ROI symmetric about the image centre, which lies on a pixel
    # edge for the even sensor dimensions (docs/protocol.md); pixel quantisation changes
    # the covered sample area by at most one pixel column/row.
    width = max(2, 2 * int(round(fraction * sample_w / 2.0)))
    height = max(2, 2 * int(round(fraction * sample_h / 2.0)))
    x0 = int(round(info.width / 2.0 - width / 2.0))
    y0 = int(round(info.height / 2.0 - height / 2.0))
    roi = Roi(x0, y0, width, height)
    reason = roi_problem(info, view, roi, sample_size_mm=sample_size_mm, margin_px=margin_px)
    if reason:
        raise GeometryError(reason)
    return roi


def roi_problem(
    info: SensorInfo, view: float, roi: Roi, *, sample_size_mm: float = SAMPLE_SIZE_MM, margin_px: float = 2.0
) -> str | None:
    """Why ``roi`` is not a valid radiance window on the sample's image at ``view``, or None."""
    sample_w, sample_h = sample_image_size(info, view, sample_size_mm)
    cx, cy = info.width / 2.0, info.height / 2.0
    left, right = cx - sample_w / 2 + margin_px, cx + sample_w / 2 - margin_px
    top, bottom = cy - sample_h / 2 + margin_px, cy + sample_h / 2 - margin_px
    if roi.width < 2 or roi.height < 2:
        return (
            f"the ROI at view={view:g} deg would be {roi.width} x {roi.height} pixels; the "
            "sample's image is too narrow at this grazing angle (at least 2 x 2 needed)"
        )
    if roi.x0 < left or roi.x0 + roi.width > right or roi.y0 < top or roi.y0 + roi.height > bottom:
        return (
            f"ROI {roi} is not inside the sample's image at view={view:g} deg "
            f"(x {left:.1f}..{right:.1f}, y {top:.1f}..{bottom:.1f} with a {margin_px:g}-pixel margin)"
        )
    if roi.x0 < 0 or roi.y0 < 0 or roi.x0 + roi.width > info.width or roi.y0 + roi.height > info.height:
        return f"ROI {roi} extends beyond the {info.width} x {info.height} sensor"
    return None
