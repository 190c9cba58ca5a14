"""Type stubs of the extension module (src/python.rs); the package `crease` re-exports its
classes. The functions are called through `crease.extract`, `crease.extract_file` and
`crease.read` (src/python/crease/__init__.py)."""

import os
from pathlib import Path
from typing import Any, Callable, Iterator, Optional, Sequence, Union, overload

import numpy as np
import numpy.typing as npt

__version__: str

_Progress = Optional[Callable[[str, int, int, str], Any]]

class InputError(ValueError):
    """Bad input data: a point file missing, unreadable or malformed, a damaged run directory,
    or points that are not a cloud. The message is the command line's one line, naming the file
    (``<memory>`` or ``points`` for an array); the file is also ``filename``.

    Example::

        >>> try:
        ...     crease.extract_file("truncated.las", "run")
        ... except crease.InputError as e:
        ...     print(e.filename, e)
        truncated.las truncated.las: file is truncated
    """

    filename: Optional[str]

class Curve:
    """One feature curve: an ordered run of vertices, each with two surface normals.

    Example::

        >>> c = curves[0]
        >>> c.points.shape, c.normals.shape, c.corner.sum(), c.kind, c.angle
        ((57, 3), (57, 2, 3), 2, 'line', 90.0)
    """

    @property
    def id(self) -> int:
        """Identifier, unique within the curves."""
    @property
    def closed(self) -> bool:
        """True if the last vertex connects back to the first."""
    @property
    def points(self) -> npt.NDArray[np.float64]:
        """The vertices' positions, a (K, 3) float64 array."""
    @property
    def normals(self) -> npt.NDArray[np.float32]:
        """The unit normals of the two surfaces that meet at each vertex, a (K, 2, 3) float32
        array (each pointing away from the other surface's side: out of the solid at a convex
        crease; zeros where unknown)."""
    @property
    def corner(self) -> npt.NDArray[np.bool_]:
        """Which vertices are corners (three or more surfaces meet), a (K,) bool array."""
    @property
    def confidence(self) -> float:
        """How sure crease is that the curve is a feature of the surface, 0 to 1."""
    @property
    def shape(self) -> str:
        """``convex``, ``concave`` or ``unknown`` (needs ``outside``, or E57 scan positions)."""
    @property
    def length(self) -> float:
        """Length, in model units."""
    @property
    def angle(self) -> Optional[float]:
        """Mean dihedral angle in degrees: 90 at a cube's edge, towards 180 as the crease
        flattens; None if no normals are known."""
    @property
    def start(self) -> str:
        """How the curve starts: ``corner``, ``free`` or ``closed``."""
    @property
    def end(self) -> str:
        """How the curve ends: ``corner``, ``free`` or ``closed``."""
    @property
    def kind(self) -> Optional[str]:
        """``line``, ``arc``, ``circle``, ``spline``, ``polyline`` or ``mixed``, from the curve's typed pieces;
        None where their tolerance is not known (curves read without their run's report)."""
    @property
    def radius(self) -> Optional[float]:
        """The radius of a curve that is one arc or one circle, else None."""
    @property
    def attributes(self) -> dict[str, Any]:
        """The attributes the GeoJSON and GeoPackage give the curve: id, closed, length,
        confidence, angle, shape, start, end, corners (vertex indices as text), kind, radius."""
    def __len__(self) -> int:
        """Number of vertices."""

class Curves(Sequence[Curve]):
    """Feature curves, a sequence of :class:`Curve` with their CRS.

    Example::

        >>> curves = crease.extract(points)
        >>> len(curves), curves.crs
        (27, 'EPSG:32632')
        >>> long = [c for c in curves if c.length > 1.0]
        >>> points, ids = curves.to_numpy()
        >>> curves.write("curves.gpkg")
        >>> curves.to_geopandas().to_file("curves.fgb")
    """

    def __len__(self) -> int: ...
    @overload
    def __getitem__(self, index: int) -> Curve: ...
    @overload
    def __getitem__(self, index: slice) -> Sequence[Curve]: ...
    def __iter__(self) -> Iterator[Curve]: ...
    @property
    def crs(self) -> Optional[str]:
        """The CRS as ``EPSG:N``, else its WKT, else None."""
    @property
    def crs_wkt(self) -> Optional[str]:
        """The CRS's WKT, where the input carried one."""
    @property
    def tolerance(self) -> Optional[float]:
        """The tolerance of the typed pieces that give each curve's kind and radius: the larger
        of 3 noise deviations and half the point spacing."""
    @property
    def report(self) -> Optional[dict[str, Any]]:
        """What the extraction reported: the parameters resolved, tau, the counts per stage and
        the seconds (for curves read from a run directory, its ``report.json``); None for curves
        read from a file alone."""
    def to_numpy(self) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.uint32]]:
        """Every vertex, curve after curve: ``(points, curve_ids)``, an (V, 3) float64 array and
        the (V,) ids of the curves the vertices belong to.

        Example::

            >>> points, ids = curves.to_numpy()
            >>> points[ids == curves[0].id]      # the first curve's vertices
        """
    def write(self, path: Union[str, os.PathLike[str]], format: Optional[str] = None) -> Path:
        """Writes the curves to ``path`` as ``format``: ``obj``, ``ply``, ``geojson``, ``gpkg``,
        ``dxf`` or ``json`` (the typed pieces); by default from the file's extension. The files
        are those ``crease extract`` writes. Raises OSError if the file cannot be written.

        Example::

            >>> curves.write("edges.dxf")
            >>> curves.write("edges.txt", format="geojson")
        """
    def to_geopandas(self) -> Any:
        """A ``geopandas.GeoDataFrame``: a LineString Z a curve (closed ones end on their first
        vertex), its attributes as columns, in the curves' CRS. Needs geopandas.

        Example::

            >>> gdf = curves.to_geopandas()
            >>> gdf[gdf.kind == "arc"].to_file("arcs.gpkg", layer="arcs")
        """

class Run:
    """A run directory's result, as :func:`crease.extract_file` returns it.

    Example::

        >>> run = crease.extract_file("scan.laz", "run")
        >>> run.report["counts"]["curves"], run.report["params"]["kappa"]
        >>> run.curves().to_geopandas()
    """

    @property
    def dir(self) -> Path:
        """The run directory."""
    @property
    def report(self) -> dict[str, Any]:
        """``report.json`` as a dict: inputs, resolved parameters, counts per stage, seconds per
        pass, peak memory, tiles, warnings, CRS, ``resumed``."""
    @property
    def labels(self) -> list[Path]:
        """The labelled copies of the inputs (``label_points``): ``labels/NAME.laz`` (``.ply`` for
        PLY input) with the extra dimensions ``edge_distance``, ``curve_id`` and ``edge``."""
    @property
    def outputs(self) -> list[Path]:
        """The files written: the curve files, ``preview.png``, ``report.json``."""
    def curves(self) -> Curves:
        """The curves the run wrote."""

def extract(points: npt.NDArray[np.float64], options: Optional[dict[str, Any]] = None, progress: _Progress = None) -> Curves: ...
def extract_file(paths: list[str], out_dir: str, options: Optional[dict[str, Any]] = None, progress: _Progress = None) -> Run: ...
def read(path: str, tolerance: Optional[float] = None) -> Curves: ...
