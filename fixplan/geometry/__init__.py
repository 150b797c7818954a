"""Workpiece shapes and closed-form distances to a point (body frame)."""

from fixplan.geometry.shapes import (
    Box,
    Cylinder,
    Disk,
    Polygon,
    Projection,
    Rectangle,
    Shape,
    Sphere,
)

__all__ = ["Box", "Cylinder", "Disk", "Polygon", "Projection", "Rectangle", "Shape", "Sphere"]
