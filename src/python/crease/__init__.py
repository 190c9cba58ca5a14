"""crease: sharp feature curves (creases, edges, corners) from point clouds.

numpy in, curves out::

    >>> import crease, laspy
    >>> curves = crease.extract(laspy.read("part.las"))       # or an (N, 3) float64 array
    >>> len(curves), curves[0].points.shape
    (12, (57, 3))
    >>> curves.write("curves.gpkg")

and the big runs, out of core and resumable, from a script or a notebook::

    >>> run = crease.extract_file("scans/", "run", memory="4G")   # Ctrl-C stops; call again to resume
    >>> run.report["counts"]["curves"]
    >>> crease.read("run").to_geopandas()

Lengths are in the cloud's own units; every parameter defaults from the point spacing, as on
the command line (``crease extract --help`` says what each does). Errors carry the command
line's one-line messages: bad input data raises :class:`InputError` (a ``ValueError``, naming
the file), a bad argument ``ValueError``, a failed write ``OSError``.
"""

from __future__ import annotations

import os
import sys
from typing import Any, Callable, Iterable, Optional, Union

import numpy as np

from . import _crease
from ._crease import Curve, Curves, InputError, Run, __version__

__all__ = ["extract", "extract_file", "read", "Curves", "Curve", "Run", "InputError", "__version__"]

PathLike = Union[str, "os.PathLike[str]"]
Progress = Union[bool, Callable[[str, int, int, str], Any], None]


def extract(points: Any, *, progress: Progress = False, **params: Any) -> Curves:
    """Extracts the feature curves of a point cloud held in memory.

    ``points`` is an (N, 3) array of x, y, z (float64 and C-contiguous is used as it lies, without
    a copy; anything else is converted once), or any object with ``x``, ``y`` and ``z``: a
    ``laspy.LasData`` (scaled exactly as ``crease extract`` scales the file), a structured array
    with fields x, y, z or X, Y, Z (a PDAL pipeline's array), a pandas DataFrame, a dict.

    The method parameters are those of ``crease extract``, by the same names: ``kappa``,
    ``fit_radius``, ``rmls_radius``, ``tau``, ``step``, ``max_turn``, ``min_angle`` (degrees),
    ``seed``, ``evaluate_per_fit``, ``model`` (``"balls"``, ``"cells"`` or ``"patches"``); and ``min_confidence``,
    ``min_length``, ``outside`` (``"up"``, ``"unknown"`` or scanner positions as an (M, 3) array),
    ``crs`` (``"EPSG:N"`` or a WKT, carried to the outputs), ``memory`` (bytes or ``"2G"``),
    ``tile_size`` and ``threads``. The curves are the same at any thread count, and the same as
    ``crease extract`` gives on the same points.

    The interpreter is released while it runs; Ctrl-C stops it within about a second.
    ``progress`` is True for a bar (tqdm's, in a notebook too, where tqdm is installed), or a
    callable ``progress(stage, done, total, unit)``.

    Example::

        >>> pts = np.random.default_rng(1).random((100_000, 3))   # points in a unit cube
        >>> curves = crease.extract(pts, min_confidence=0.5)
        >>> for c in curves:
        ...     print(c.id, c.kind, c.length, c.points.shape)
    """
    array = _as_points(points)
    options = dict(params)
    if "outside" in options and not isinstance(options["outside"], (str, type(None))):
        options["outside"] = _positions(options["outside"])
    return _with_progress(progress, lambda p: _crease.extract(array, options, p))


def extract_file(
    paths: Union[PathLike, Iterable[PathLike]],
    out_dir: PathLike,
    *,
    memory: Union[int, str, None] = None,
    threads: Optional[int] = None,
    progress: Progress = True,
    **params: Any,
) -> Run:
    """Extracts the curves of point files (LAS, LAZ, COPC, PLY, E57, text) into a run directory,
    out of core: what ``crease extract PATHS -o OUT_DIR`` does.

    ``paths`` is a file or directory or a list of them (a directory is one cloud made of all its
    point files). The run is resumable: stopped by Ctrl-C (KeyboardInterrupt, within about a
    second; in a notebook, the interrupt button) or killed, the same call goes on where it
    stopped; a finished run given other output settings only writes its outputs again.

    ``memory`` is the budget (bytes, or ``"4G"``; default half the machine's memory), which sizes
    the tiles. Besides the parameters of :func:`extract`: ``formats`` (a list of ``"obj"``,
    ``"ply"``, ``"geojson"``, ``"gpkg"``, ``"dxf"``, ``"json"``), ``force``, ``recursive``,
    ``work_dir``, ``clean``, ``label_points`` (a labelled copy of each input file, see
    :attr:`Run.labels`), and the input filters ``classes``, ``keep_noise``, ``columns``,
    ``skip_lines``, ``bounds`` (4 or 6 numbers).

    The interpreter is released while it runs. ``progress`` draws a bar per stage (tqdm's where
    installed, a notebook widget in a notebook), or False, or a callable
    ``progress(stage, done, total, unit)``; an exception raised by the callable stops the run as
    Ctrl-C does.

    Example::

        >>> run = crease.extract_file(["tile1.laz", "tile2.laz"], "run", memory="2G", formats=["gpkg"])
        >>> run.report["counts"]["curves"], run.outputs
        >>> curves = run.curves()
    """
    if isinstance(paths, (str, bytes, os.PathLike)):
        paths = [paths]
    files = [os.fspath(p) for p in paths]
    options = dict(params, memory=memory, threads=threads)
    if "outside" in options and not isinstance(options["outside"], (str, type(None))):
        options["outside"] = _positions(options["outside"])
    if isinstance(options.get("formats"), str):
        options["formats"] = [options["formats"]]
    if isinstance(options.get("classes"), int):
        options["classes"] = [options["classes"]]
    return _with_progress(progress, lambda p: _crease.extract_file(files, os.fspath(out_dir), options, p))


def read(path: PathLike, *, tolerance: Optional[float] = None) -> Curves:
    """Reads curves back: a finished run directory (its ``curves.ply``, else ``curves.obj``, with
    the CRS and the typed pieces' tolerance from its ``report.json``), or a crease PLY or OBJ curve
    file. ``tolerance`` sets that of the typed pieces (each curve's ``kind`` and ``radius``) where
    no report gives it.

    Example::

        >>> curves = crease.read("run")
        >>> points, ids = curves.to_numpy()
    """
    return _crease.read(os.fspath(path), tolerance)


def _as_points(points: Any) -> np.ndarray:
    """The points as a C-contiguous (N, 3) float64 array: the array itself where it is one,
    else one conversion into a new array (no further copy)."""
    if isinstance(points, np.ndarray) and points.dtype.names is None or isinstance(points, (list, tuple)):
        a = np.asarray(points)
        if a.ndim != 2 or a.shape[1] != 3:
            raise InputError(f"points: an (N, 3) array of x, y, z is needed, not one of shape {a.shape}")
        if not (np.issubdtype(a.dtype, np.integer) or np.issubdtype(a.dtype, np.floating)):
            raise InputError(f"points: the coordinates must be numbers, not {a.dtype}")
        return np.ascontiguousarray(a, dtype=np.float64)
    header = getattr(points, "header", None)
    if hasattr(header, "scales") and hasattr(header, "offsets") and hasattr(points, "X"):
        # A laspy.LasData: its stored integers scaled as crease scales a LAS file (x * scale +
        # offset, the same bits), straight into the array.
        raw = [np.asarray(getattr(points, name)) for name in "XYZ"]
        out = np.empty((len(raw[0]), 3))
        for k in range(3):
            np.multiply(raw[k], header.scales[k], out=out[:, k])
            out[:, k] += header.offsets[k]
        return out
    columns = _columns(points)
    if columns is None:
        raise TypeError(
            "points: an (N, 3) array, or an object with x, y and z (a laspy.LasData, a structured array, a DataFrame, a dict), "
            f"not {type(points).__name__}"
        )
    n = len(columns[0])
    if any(len(c) != n for c in columns):
        raise InputError(f"points: x, y and z differ in length ({', '.join(str(len(c)) for c in columns)})")
    out = np.empty((n, 3))
    for k, c in enumerate(columns):
        out[:, k] = c
    return out


def _columns(points: Any) -> Optional[list]:
    """x, y and z of a structured array, a mapping or an object, if it has them."""
    names = getattr(getattr(points, "dtype", None), "names", None)
    for xyz in ("xyz", "XYZ"):
        if names is not None:
            if all(n in names for n in xyz):
                return [points[n] for n in xyz]
            continue
        try:
            if all(n in points for n in xyz):
                return [points[n] for n in xyz]
        except TypeError:
            pass
        if all(hasattr(points, n) for n in xyz):
            return [getattr(points, n) for n in xyz]
    return None


def _positions(value: Any) -> str:
    """Scanner positions as ``--outside`` takes them: ``X,Y,Z;X,Y,Z``."""
    a = np.asarray(value, dtype=np.float64).reshape(-1, 3)
    return ";".join(",".join(repr(float(x)) for x in p) for p in a)


def _with_progress(progress: Progress, call: Callable[[Any], Any]) -> Any:
    if progress is True:
        bar = _Bar()
        try:
            return call(bar)
        finally:
            bar.close()
    if progress is False or progress is None:
        return call(None)
    if not callable(progress):
        raise TypeError(f"progress: True, False or a callable progress(stage, done, total, unit), not {progress!r}")
    return call(progress)


class _Bar:
    """A bar per stage: tqdm's (a widget in a notebook) where installed, else a line on stderr."""

    def __init__(self) -> None:
        try:
            from tqdm.auto import tqdm
        except ImportError:
            tqdm = None
        self._tqdm = tqdm
        self._bar: Any = None
        self._stage: Optional[str] = None
        self._live = bool(getattr(sys.stderr, "isatty", lambda: False)()) or "ipykernel" in sys.modules

    def __call__(self, stage: str, done: int, total: int, unit: str) -> None:
        if stage != self._stage:
            self.close()
            self._stage = stage
            if self._tqdm is not None:
                self._bar = self._tqdm(total=total, desc=stage, unit=" " + unit.rstrip("s"), unit_scale=unit == "points", leave=True)
            elif not self._live:
                sys.stderr.write(f"crease: {stage}: {total} {unit}\n")
        if self._bar is not None:
            self._bar.update(done - self._bar.n)
        elif self._live:
            sys.stderr.write(f"\rcrease: {stage}: {done}/{total} {unit}")
            sys.stderr.flush()

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()
            self._bar = None
        elif self._live and self._stage is not None:
            sys.stderr.write("\n")
        self._stage = None
