//! The Python extension module `crease._crease` (cargo feature `python`, built by maturin from
//! `pyproject.toml`), which the package `crease` in `src/python/crease/` wraps: there the
//! inputs are turned into an (N, 3) float64 array (laspy files, structured arrays, data frames)
//! and the progress bars drawn; here the library runs and its results become Python objects.
//!
//! - `extract` runs [`run::extract_cloud`] on the array as it lies in memory: a C-contiguous
//!   float64 array is viewed as points, not copied ([`points_of`]).
//! - `extract_file` runs [`run::run_extract`], the resumable run over files, as `crease
//!   extract` does.
//! - Both run on a thread of their own with the interpreter released, while the calling
//!   thread polls every [`POLL`] for Ctrl-C (Python's KeyboardInterrupt) and draws progress
//!   from a [`Watch`]. An interrupt sets the run's [`Cancel`], which the run checks between
//!   blocks of work, so it stops within a second and a run directory resumes where it stopped.
//!   (Nothing calls into Python from the run's threads: they never wait for the interpreter.)
//! - Errors become Python exceptions with the library's one-line messages: bad input data
//!   `InputError` (a `ValueError`, with the file as its `filename`), a bad argument
//!   `ValueError`, a failed write `OSError`, an interrupt `KeyboardInterrupt`.

use crate::cancel::Cancel;
use crate::crs::Crs;
use crate::curves::{typed, Format, Outside, Polyline};
use crate::error::Error;
use crate::extract::params::Model;
use crate::extract::Params;
use crate::io::{Filter, TextColumns};
use crate::points::Bounds;
use crate::progress::{Mode, Snapshot, Watch};
use crate::run::{self, RunOptions};
use glam::DVec3;
use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::conversion::FromPyObjectOwned;
use pyo3::exceptions::{PyIndexError, PyKeyboardInterrupt, PyOSError, PyRuntimeError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PySlice};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

pyo3::create_exception!(
    crease,
    InputError,
    PyValueError,
    "Bad input data: a point file missing, unreadable or malformed, a damaged run directory, or points that are not a cloud. The message is the command line's, naming the file (`<memory>` for an array) and the problem; the file is also the exception's `filename`."
);

/// How often the calling thread looks for Ctrl-C and progress while a run works.
const POLL: Duration = Duration::from_millis(50);

/// The Python exception for a library error, with its message.
fn py_err(e: Error) -> PyErr {
    let msg = e.to_string();
    let (err, file) = match &e {
        Error::Input { path, .. } | Error::Damaged { path, .. } => (InputError::new_err(msg), Some(path.clone())),
        Error::Usage(_) => (PyValueError::new_err(msg), None),
        Error::Output { path, .. } => (PyOSError::new_err(msg), Some(path.clone())),
        Error::Interrupted => (PyKeyboardInterrupt::new_err(msg), None),
        Error::Panic(..) => (PyRuntimeError::new_err(msg), None),
    };
    if let Some(file) = file {
        Python::attach(|py| err.value(py).setattr("filename", file.to_string_lossy().into_owned())).ok();
    }
    err
}

/// Keyword options, taken one by one; what is left over is refused as Python refuses an
/// unknown keyword argument.
struct Options<'py> {
    dict: Bound<'py, PyDict>,
    func: &'static str,
}

impl<'py> Options<'py> {
    fn new(func: &'static str, given: Option<&Bound<'py, PyDict>>, py: Python<'py>) -> PyResult<Self> {
        // (A copy: the caller's dict is left as it was.)
        let dict = match given {
            Some(d) => d.copy()?,
            None => PyDict::new(py),
        };
        Ok(Options { dict, func })
    }

    /// The option `name`, if given and not None.
    fn take<T: FromPyObjectOwned<'py>>(&self, name: &str) -> PyResult<Option<T>> {
        let Some(v) = self.dict.get_item(name)? else { return Ok(None) };
        self.dict.del_item(name)?;
        if v.is_none() {
            return Ok(None);
        }
        v.extract::<T>().map(Some).map_err(|e| {
            let e: PyErr = e.into();
            PyTypeError::new_err(format!("{}(): {name}: {}", self.func, e.value(v.py())))
        })
    }

    /// Refuses any option not taken.
    fn finish(self) -> PyResult<()> {
        match self.dict.keys().iter().next() {
            Some(k) => Err(PyTypeError::new_err(format!("{}() got an unexpected keyword argument {}", self.func, k.repr()?))),
            None => Ok(()),
        }
    }

    /// The method parameters, as `crease extract` takes them (`max_turn`, `min_angle` in
    /// degrees), checked.
    fn params(&self) -> PyResult<Params> {
        let model = match self.take::<String>("model")? {
            Some(m) => Some(Model::parse(&m).ok_or_else(|| PyValueError::new_err(format!("'{m}' is not a model: balls, cells or patches")))?),
            None => None,
        };
        let p = Params {
            kappa: self.take("kappa")?,
            fit_radius: self.take("fit_radius")?,
            rmls_radius: self.take("rmls_radius")?,
            tau: self.take("tau")?,
            step: self.take("step")?,
            max_turn_deg: self.take("max_turn")?,
            min_angle_deg: self.take("min_angle")?,
            seed: self.take("seed")?,
            evaluate_per_fit: self.take("evaluate_per_fit")?,
            model,
        };
        p.validate().map_err(py_err)?;
        Ok(p)
    }

    /// The run options both entry points take: memory, tile size, threads, the output
    /// filters, the CRS and where the scanners stood.
    fn run_options(&self, watch: &Watch, cancel: &Cancel) -> PyResult<(RunOptions, Option<usize>)> {
        let defaults = RunOptions::default();
        let memory = match self.dict.get_item("memory")? {
            Some(v) if v.extract::<String>().is_ok() => {
                let s: String = self.take("memory")?.unwrap_or_default();
                Some(crate::mem::parse_size(&s).map_err(|e| PyValueError::new_err(format!("--memory {e}")))?)
            }
            _ => self.take::<u64>("memory")?,
        };
        let outside = match self.take::<String>("outside")? {
            Some(s) => Some(Outside::parse(&s).map_err(|e| PyValueError::new_err(format!("--outside {e}")))?),
            None => None,
        };
        let crs = match self.take::<String>("crs")? {
            Some(s) => Some(Crs::parse_user(&s).map_err(py_err)?),
            None => None,
        };
        let threads = self.take::<usize>("threads")?;
        if let Some(n) = threads {
            run::check_threads(n).map_err(py_err)?;
        }
        let opts = RunOptions {
            memory: memory.unwrap_or(defaults.memory),
            tile_size: self.take("tile_size")?,
            progress: Mode::Quiet,
            watch: Some(watch.clone()),
            cancel: cancel.clone(),
            min_confidence: self.take("min_confidence")?.unwrap_or(defaults.min_confidence),
            min_length: self.take("min_length")?.unwrap_or(defaults.min_length),
            assign_crs: crs,
            outside,
            ..defaults
        };
        opts.validate().map_err(py_err)?;
        Ok((opts, threads))
    }
}

/// Runs `work` on a thread of its own (in a pool of `threads`, if given) with the interpreter
/// released, polling for Ctrl-C and progress meanwhile. An interrupt, or an exception raised by
/// `progress`, sets `cancel`; once the run has stopped, that exception is raised.
fn run_released<T: Send>(
    py: Python<'_>,
    cancel: &Cancel,
    watch: &Watch,
    progress: Option<&Bound<'_, PyAny>>,
    threads: Option<usize>,
    work: impl FnOnce() -> crate::Result<T> + Send,
) -> PyResult<T> {
    let pool = match threads {
        Some(n) => Some(rayon::ThreadPoolBuilder::new().num_threads(n.max(1)).build().map_err(|e| PyValueError::new_err(e.to_string()))?),
        None => None,
    };
    let (done_tx, done) = crossbeam_channel::bounded::<()>(1);
    std::thread::scope(|s| {
        let worker = s.spawn(move || {
            let r = match &pool {
                Some(p) => p.install(work),
                None => work(),
            };
            // (The sender goes with this thread, so a panic wakes the poller too.)
            let _ = done_tx.send(());
            r
        });
        let mut stop: Option<PyErr> = None;
        let mut shown: Option<Snapshot> = None;
        loop {
            let finished = py.detach(|| !matches!(done.recv_timeout(POLL), Err(crossbeam_channel::RecvTimeoutError::Timeout)));
            if stop.is_none()
                && let Err(e) = py.check_signals()
            {
                cancel.set();
                stop = Some(e);
            }
            if let (Some(p), None) = (progress, &stop) {
                let now = watch.get();
                if now.number > 0 && shown.as_ref() != Some(&now) {
                    if let Err(e) = p.call1((now.stage.as_str(), now.done, now.total, now.unit.as_str())) {
                        cancel.set();
                        stop = Some(e);
                    }
                    shown = Some(now);
                }
            }
            if finished {
                break;
            }
        }
        let result = worker.join();
        if let Some(e) = stop {
            return Err(e);
        }
        match result {
            Ok(r) => r.map_err(py_err),
            Err(payload) => Err(py_err(Error::panic("extraction", payload))),
        }
    })
}

/// Views a C-contiguous (N, 3) float64 array as points, without copying it.
fn points_of<'a>(a: &'a PyReadonlyArray2<'_, f64>) -> PyResult<&'a [DVec3]> {
    let shape = a.shape();
    if shape.len() != 2 || shape[1] != 3 {
        return Err(InputError::new_err(format!("points: an (N, 3) array of x, y, z is needed, not one of shape {shape:?}")));
    }
    if !a.is_c_contiguous() {
        return Err(PyValueError::new_err("points: the array must be C-contiguous (numpy.ascontiguousarray makes it so)"));
    }
    let flat = a.as_slice().map_err(|e| PyValueError::new_err(format!("points: {e}")))?;
    bytemuck::try_cast_slice(flat).map_err(|e| PyValueError::new_err(format!("points: the array's memory cannot be read as points ({e:?})")))
}

/// `crease.extract`: the curves of an (N, 3) float64 array.
#[pyfunction]
#[pyo3(signature = (points, options=None, progress=None))]
fn extract(py: Python<'_>, points: PyReadonlyArray2<'_, f64>, options: Option<&Bound<'_, PyDict>>, progress: Option<&Bound<'_, PyAny>>) -> PyResult<Curves> {
    let o = Options::new("extract", options, py)?;
    let params = o.params()?;
    let (watch, cancel) = (Watch::default(), Cancel::default());
    let (opts, threads) = o.run_options(&watch, &cancel)?;
    o.finish()?;
    let pts = points_of(&points)?;
    let x = run_released(py, &cancel, &watch, progress, threads, || run::extract_cloud(pts, &params, &opts))?;
    let report = serde_json::json!({"params": x.params, "tau": x.tau, "counts": x.counts, "seconds": x.seconds});
    Ok(Curves {
        curves: Arc::new(x.curves),
        crs: opts.assign_crs.clone().unwrap_or_default(),
        tolerance: Some(typed::tolerance(x.params.kappa, x.params.noise)),
        report: Some(json_to_py(py, &report)?),
    })
}

/// `crease.extract_file`: the resumable run over point files into a run directory.
#[pyfunction]
#[pyo3(signature = (paths, out_dir, options=None, progress=None))]
fn extract_file(
    py: Python<'_>,
    paths: Vec<PathBuf>,
    out_dir: PathBuf,
    options: Option<&Bound<'_, PyDict>>,
    progress: Option<&Bound<'_, PyAny>>,
) -> PyResult<Run> {
    let o = Options::new("extract_file", options, py)?;
    let params = o.params()?;
    let (watch, cancel) = (Watch::default(), Cancel::default());
    let (mut opts, threads) = o.run_options(&watch, &cancel)?;
    if let Some(names) = o.take::<Vec<String>>("formats")? {
        let formats = names
            .iter()
            .map(|n| format_named(n).ok_or_else(|| PyValueError::new_err(format!("'{n}' is not a curve format: {}", format_names()))))
            .collect::<PyResult<Vec<_>>>()?;
        opts.formats = formats;
    }
    opts.force = o.take("force")?.unwrap_or(false);
    opts.recursive = o.take("recursive")?.unwrap_or(false);
    opts.work_dir = o.take("work_dir")?;
    opts.clean = o.take("clean")?.unwrap_or(false);
    opts.label_points = o.take("label_points")?.unwrap_or(false);
    let columns = match o.take::<String>("columns")? {
        Some(c) => Some(TextColumns::parse(&c, o.take("skip_lines")?.unwrap_or(0)).map_err(|e| PyValueError::new_err(format!("--columns {e}")))?),
        None => None,
    };
    let bounds = match o.take::<Vec<f64>>("bounds")? {
        Some(b) => Some(Bounds::from_list(&b).map_err(|e| PyValueError::new_err(format!("--bounds {e}")))?),
        None => None,
    };
    let filter = Filter { classes: o.take("classes")?, keep_noise: o.take("keep_noise")?.unwrap_or(false), text: columns, bounds };
    o.finish()?;
    if paths.is_empty() {
        return Err(PyValueError::new_err("no input files"));
    }
    let report = run_released(py, &cancel, &watch, progress, threads, || run::run_extract(&paths, &out_dir, &params, &filter, &opts))?;
    let tolerance = typed::tolerance(report.params.kappa, report.params.noise);
    let json = serde_json::to_value(&report).map_err(|e| PyRuntimeError::new_err(e.to_string()))?;
    Ok(Run { dir: out_dir, report: json_to_py(py, &json)?, crs: report.crs.clone(), tolerance })
}

/// The curve format called `name` (`obj`, `ply`, `geojson`, `gpkg`, `dxf`, `json`).
fn format_named(name: &str) -> Option<Format> {
    Format::ALL.into_iter().find(|f| f.file_name().strip_prefix("curves.") == Some(name.to_ascii_lowercase().trim_start_matches('.')))
}

fn format_names() -> String {
    Format::ALL.iter().map(|f| f.file_name().trim_start_matches("curves.")).collect::<Vec<_>>().join(", ")
}

/// A JSON value as the Python object `json.loads` makes of it.
fn json_to_py(py: Python<'_>, v: &serde_json::Value) -> PyResult<Py<PyAny>> {
    Ok(py.import("json")?.call_method1("loads", (v.to_string(),))?.unbind())
}

/// `crease.read`: the curves of a finished run directory, or of a curve file (PLY or OBJ).
#[pyfunction]
#[pyo3(signature = (path, tolerance=None))]
fn read(py: Python<'_>, path: PathBuf, tolerance: Option<f64>) -> PyResult<Curves> {
    let (file, dir) = if path.is_dir() {
        let file = ["curves.ply", "curves.obj"].iter().map(|f| path.join(f)).find(|f| f.is_file());
        (file.ok_or_else(|| py_err(Error::input(&path, "holds no curves.ply or curves.obj: not a finished crease run")))?, path.clone())
    } else {
        (path.clone(), path.parent().map(Path::to_path_buf).unwrap_or_default())
    };
    let curves = py
        .detach(|| match file.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).as_deref() {
            Some("ply") => crate::curves::read_ply(&file),
            Some("obj") => crate::curves::read_obj(&file),
            _ => Err(Error::input(&file, "not a curve file crease reads back (a crease PLY or OBJ)")),
        })
        .map_err(py_err)?;
    // (The run's report, beside its curves, gives their CRS and the typed pieces' tolerance.)
    let report: Option<serde_json::Value> = std::fs::read_to_string(dir.join("report.json"))
        .ok()
        .and_then(|s| serde_json::from_str(&s).ok())
        .filter(|_| file.file_name().is_some_and(|n| n.to_string_lossy().starts_with("curves.")));
    let crs = report.as_ref().and_then(|r| serde_json::from_value::<Crs>(r["crs"].clone()).ok()).unwrap_or_default();
    let from_report = report.as_ref().and_then(|r| Some(typed::tolerance(r["params"]["kappa"].as_f64()?, r["params"]["noise"].as_f64()?)));
    let report = report.map(|r| json_to_py(py, &r)).transpose()?;
    Ok(Curves { curves: Arc::new(curves), crs, tolerance: tolerance.or(from_report), report })
}

/// Feature curves: a sequence of Curve objects with their CRS (see the stubs for examples).
#[pyclass(frozen, module = "crease", sequence)]
struct Curves {
    curves: Arc<Vec<Polyline>>,
    crs: Crs,
    /// The tolerance of the typed pieces (a curve's kind and radius), if known.
    tolerance: Option<f64>,
    report: Option<Py<PyAny>>,
}

impl Curves {
    fn curve(&self, index: usize) -> Curve {
        Curve { all: self.curves.clone(), index, tolerance: self.tolerance }
    }
}

#[pymethods]
impl Curves {
    fn __len__(&self) -> usize {
        self.curves.len()
    }

    /// A curve by index, or a list of them by slice.
    fn __getitem__<'py>(&self, index: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
        let py = index.py();
        if let Ok(slice) = index.cast::<PySlice>() {
            let ix = slice.indices(self.curves.len() as isize)?;
            let picked: Vec<Curve> = (0..ix.slicelength).map(|k| self.curve((ix.start + k as isize * ix.step) as usize)).collect();
            return Ok(picked.into_pyobject(py)?.into_any());
        }
        let index: isize = index.extract()?;
        let n = self.curves.len() as isize;
        let i = if index < 0 { index + n } else { index };
        if !(0..n).contains(&i) {
            return Err(PyIndexError::new_err(format!("curve index {index} out of range for {n} curves")));
        }
        Ok(Bound::new(py, self.curve(i as usize))?.into_any())
    }

    fn __iter__(slf: PyRef<'_, Self>) -> CurvesIter {
        CurvesIter { curves: Curves { curves: slf.curves.clone(), crs: Crs::default(), tolerance: slf.tolerance, report: None }, next: 0 }
    }

    fn __repr__(&self) -> String {
        let vertices: usize = self.curves.iter().map(|c| c.vertices.len()).sum();
        format!("<crease.Curves: {} curves, {} vertices, CRS {}>", self.curves.len(), vertices, self.crs.summary())
    }

    /// The CRS as `EPSG:N`, else its WKT, else None.
    #[getter]
    fn crs(&self) -> Option<String> {
        match (self.crs.epsg, &self.crs.wkt) {
            (Some(code), _) => Some(format!("EPSG:{code}")),
            (None, Some(wkt)) => Some(wkt.clone()),
            (None, None) => None,
        }
    }

    /// The CRS's WKT, if the input carried one.
    #[getter]
    fn crs_wkt(&self) -> Option<String> {
        self.crs.wkt.clone()
    }

    /// The tolerance of the typed pieces that give each curve's kind and radius.
    #[getter]
    fn tolerance(&self) -> Option<f64> {
        self.tolerance
    }

    /// What the extraction reported (parameters resolved, tau, counts, seconds), or the run's
    /// `report.json`; None for curves read from a file alone.
    #[getter]
    fn report(&self, py: Python<'_>) -> Option<Py<PyAny>> {
        self.report.as_ref().map(|r| r.clone_ref(py))
    }

    /// Every vertex, `(points, curve_ids)`: an (V, 3) float64 array and the (V,) uint32 id of
    /// the curve each belongs to, curve after curve.
    fn to_numpy<'py>(&self, py: Python<'py>) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
        let flat: Vec<f64> = self.curves.iter().flat_map(|c| c.vertices.iter().flat_map(|v| v.p.to_array())).collect();
        let ids: Vec<u32> = self.curves.iter().flat_map(|c| std::iter::repeat_n(c.id, c.vertices.len())).collect();
        let n = ids.len();
        Ok((PyArray1::from_vec(py, flat).reshape([n, 3])?.into_any(), PyArray1::from_vec(py, ids).into_any()))
    }

    /// Writes the curves to `path` in `format` (default: from the file's extension).
    #[pyo3(signature = (path, format=None))]
    fn write(&self, py: Python<'_>, path: PathBuf, format: Option<&str>) -> PyResult<PathBuf> {
        let name = format.map(str::to_string).or_else(|| path.extension().map(|e| e.to_string_lossy().into_owned())).unwrap_or_default();
        let f = format_named(&name).ok_or_else(|| PyValueError::new_err(format!("{}: '{name}' is not a curve format: {}", path.display(), format_names())))?;
        let typed = matches!(f, Format::Geojson | Format::Gpkg | Format::Dxf | Format::Json);
        let tolerance = match (self.tolerance, typed) {
            (Some(t), _) => t,
            (None, false) => 0.0,
            (None, true) => {
                return Err(PyValueError::new_err(format!(
                    "{}: the curves' kinds need the typed pieces' tolerance, which curves read without their run's report.json lack: read them with tolerance= (crease takes the larger of 3 noise deviations and half the spacing)",
                    path.display()
                )))
            }
        };
        let curves = self.curves.clone();
        py.detach(|| f.write(&path, curves.as_slice(), &self.crs, tolerance)).map_err(py_err)?;
        Ok(path)
    }

    /// A geopandas GeoDataFrame, a LineString Z a curve with its attributes, in the curves'
    /// CRS (needs geopandas).
    fn to_geopandas<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyAny>> {
        slf.py().import("crease._interop")?.call_method1("to_geopandas", (slf,))
    }
}

/// Iterates over Curves.
#[pyclass(module = "crease")]
struct CurvesIter {
    curves: Curves,
    next: usize,
}

#[pymethods]
impl CurvesIter {
    fn __iter__(slf: PyRef<'_, Self>) -> PyRef<'_, Self> {
        slf
    }

    fn __next__(mut slf: PyRefMut<'_, Self>) -> Option<Curve> {
        let i = slf.next;
        (i < slf.curves.curves.len()).then(|| {
            slf.next += 1;
            slf.curves.curve(i)
        })
    }
}

/// One feature curve: its vertices (points, normals, corner flags) and attributes.
#[pyclass(frozen, module = "crease")]
struct Curve {
    all: Arc<Vec<Polyline>>,
    index: usize,
    tolerance: Option<f64>,
}

impl Curve {
    fn c(&self) -> &Polyline {
        &self.all[self.index]
    }

    /// The curve's kind and radius from its typed pieces, if the tolerance is known.
    fn kind_radius(&self) -> Option<(&'static str, Option<f64>)> {
        self.tolerance.map(|t| typed::curve_kind(&typed::pieces(self.c(), t)))
    }
}

#[pymethods]
impl Curve {
    /// Identifier, unique within the curves.
    #[getter]
    fn id(&self) -> u32 {
        self.c().id
    }

    /// True if the last vertex connects back to the first.
    #[getter]
    fn closed(&self) -> bool {
        self.c().closed
    }

    fn __len__(&self) -> usize {
        self.c().vertices.len()
    }

    fn __repr__(&self) -> String {
        let c = self.c();
        format!(
            "<crease.Curve {}: {} vertices, length {:.6}, confidence {:.3}{}>",
            c.id,
            c.vertices.len(),
            c.length(),
            c.confidence,
            if c.closed { ", closed" } else { "" }
        )
    }

    /// The vertices' positions, a (K, 3) float64 array.
    #[getter]
    fn points<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let v = &self.c().vertices;
        Ok(PyArray1::from_vec(py, v.iter().flat_map(|v| v.p.to_array()).collect()).reshape([v.len(), 3])?.into_any())
    }

    /// The two surfaces' unit normals at each vertex, a (K, 2, 3) float32 array (zeros where
    /// unknown).
    #[getter]
    fn normals<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let v = &self.c().vertices;
        Ok(PyArray1::from_vec(py, v.iter().flat_map(|v| v.n.iter().flat_map(|n| n.to_array())).collect()).reshape([v.len(), 2, 3])?.into_any())
    }

    /// Which vertices are corners (three or more surfaces meet), a (K,) bool array.
    #[getter]
    fn corner<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<bool>> {
        PyArray1::from_vec(py, self.c().vertices.iter().map(|v| v.corner).collect())
    }

    /// How sure crease is that the curve is a feature, 0 to 1.
    #[getter]
    fn confidence(&self) -> f32 {
        self.c().confidence
    }

    /// `convex`, `concave` or `unknown`.
    #[getter]
    fn shape(&self) -> &'static str {
        self.c().shape.name()
    }

    /// Length, in model units.
    #[getter]
    fn length(&self) -> f64 {
        self.c().length()
    }

    /// Mean dihedral angle in degrees (90 at a cube's edge), None if no normals are known.
    #[getter]
    fn angle(&self) -> Option<f64> {
        self.c().mean_dihedral_angle()
    }

    /// How the curve starts: `corner`, `free` or `closed`.
    #[getter]
    fn start(&self) -> &'static str {
        self.c().end_kinds()[0]
    }

    /// How the curve ends: `corner`, `free` or `closed`.
    #[getter]
    fn end(&self) -> &'static str {
        self.c().end_kinds()[1]
    }

    /// `line`, `arc`, `circle`, `spline`, `polyline` or `mixed`, from the typed pieces (None if their
    /// tolerance is not known).
    #[getter]
    fn kind(&self) -> Option<&'static str> {
        self.kind_radius().map(|k| k.0)
    }

    /// The radius of a curve that is one arc or one circle, else None.
    #[getter]
    fn radius(&self) -> Option<f64> {
        self.kind_radius().and_then(|k| k.1)
    }

    /// The attributes the GeoJSON and GeoPackage give the curve, as a dict.
    #[getter]
    fn attributes<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let c = self.c();
        let [start, end] = c.end_kinds();
        let (kind, radius) = self.kind_radius().map_or((None, None), |(k, r)| (Some(k), r));
        let d = PyDict::new(py);
        d.set_item("id", c.id)?;
        d.set_item("closed", c.closed)?;
        d.set_item("length", c.length())?;
        d.set_item("confidence", c.confidence)?;
        d.set_item("angle", c.mean_dihedral_angle())?;
        d.set_item("shape", c.shape.name())?;
        d.set_item("start", start)?;
        d.set_item("end", end)?;
        d.set_item("corners", c.corner_list())?;
        d.set_item("kind", kind)?;
        d.set_item("radius", radius)?;
        Ok(d)
    }
}

/// A run directory's result: `crease.extract_file` returns it.
#[pyclass(frozen, module = "crease")]
struct Run {
    dir: PathBuf,
    report: Py<PyAny>,
    crs: Crs,
    tolerance: f64,
}

#[pymethods]
impl Run {
    /// The run directory.
    #[getter]
    fn dir(&self) -> PathBuf {
        self.dir.clone()
    }

    /// `report.json`, as a dict.
    #[getter]
    fn report(&self, py: Python<'_>) -> Py<PyAny> {
        self.report.clone_ref(py)
    }

    /// The outputs written (curve files, `preview.png`, `report.json`).
    #[getter]
    fn outputs(&self) -> Vec<PathBuf> {
        run::OUTPUTS.iter().map(|f| self.dir.join(f)).filter(|f| f.is_file()).collect()
    }

    /// The labelled copies of the inputs (`label_points`), one per input file: `labels/NAME.laz`
    /// (or `.ply` for PLY input), with the extra dimensions `edge_distance`, `curve_id` and `edge`.
    #[getter]
    fn labels(&self, py: Python<'_>) -> PyResult<Vec<PathBuf>> {
        match self.report.bind(py).get_item("labels") {
            Ok(v) => v.extract(),
            Err(_) => Ok(Vec::new()),
        }
    }

    /// The curves the run wrote.
    fn curves(&self, py: Python<'_>) -> PyResult<Curves> {
        let c = read(py, self.dir.clone(), Some(self.tolerance))?;
        Ok(Curves { crs: self.crs.clone(), ..c })
    }

    fn __repr__(&self, py: Python<'_>) -> String {
        let curves = self.report.bind(py).get_item("counts").and_then(|c| c.get_item("curves")).map(|c| c.to_string()).unwrap_or_default();
        format!("<crease.Run {}: {curves} curves>", self.dir.display())
    }
}

#[pymodule]
#[pyo3(name = "_crease")]
fn crease_module(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(extract, m)?)?;
    m.add_function(wrap_pyfunction!(extract_file, m)?)?;
    m.add_function(wrap_pyfunction!(read, m)?)?;
    m.add_class::<Curves>()?;
    m.add_class::<Curve>()?;
    m.add_class::<Run>()?;
    m.add("InputError", m.py().get_type::<InputError>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
