"""Conversions to other libraries' types, imported only when asked for."""

from __future__ import annotations

from typing import Any

import numpy as np


def to_geopandas(curves: Any) -> Any:
    """A GeoDataFrame: one LineString Z a curve (a closed curve ends on its first vertex, as in
    the GeoJSON), its attributes as columns, in the curves' CRS."""
    try:
        import geopandas
        import shapely
    except ImportError as e:
        raise ImportError("Curves.to_geopandas needs geopandas (pip install geopandas)") from e
    rows, lines = [], []
    for c in curves:
        rows.append(c.attributes)
        pts = c.points
        if c.closed and len(pts) > 0:
            pts = np.vstack([pts, pts[:1]])
        lines.append(shapely.LineString(pts) if len(pts) >= 2 else None)
    columns = ["id", "closed", "length", "confidence", "angle", "shape", "start", "end", "corners", "kind", "radius"]
    return geopandas.GeoDataFrame(rows, columns=columns, geometry=lines, crs=curves.crs)
