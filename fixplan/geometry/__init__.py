"""Workpiece shapes and closed-form distances to a point (body frame); triangle-mesh parts."""

from fixplan.geometry.mesh import Mesh
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

__all__ = ["Box", "Cylinder", "Disk", "Mesh", "Polygon", "Projection", "Rectangle", "Shape", "Sphere"]
