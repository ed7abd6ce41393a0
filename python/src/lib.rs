//! `residency._native`: the Rust libraries as a CPython extension module, wrapped by the
//! `residency` package (`python/residency/__init__.py`). Errors are `residency.ResidencyError`
//! with the message the command line prints for the same failure.

mod conversion;
mod region_arrays;
mod rendering;
mod server;

use numpy::{PyArray1, PyArrayMethods};
use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use residency_store::location::{LocationError, ObjectStoreOptions, StoreLocation};

create_exception!(
    _native,
    ResidencyError,
    PyException,
    "A failure of a Residency call, with the message the command line prints for it."
);

/// An error as `ResidencyError`, its message the command line's (the chain joined as
/// [`error_chain`](residency_schemas::error_chain) joins it).
fn residency_error(e: &(dyn std::error::Error + 'static)) -> PyErr {
    ResidencyError::new_err(residency_schemas::error_chain::error_chain(e))
}

/// The report `ingest inspect STORE` prints: the store's version, multiscales, levels, arrays,
/// codecs and region metadata. `store` is a folder or `s3://BUCKET/PREFIX`; `s3_endpoint` an
/// S3-compatible server's URL (default: `AWS_ENDPOINT_URL`, else AWS).
///
/// # Errors
/// `ResidencyError` where the store cannot be read, with `ingest inspect`'s message.
#[pyfunction]
#[pyo3(signature = (store, *, s3_endpoint = None))]
fn inspect(py: Python<'_>, store: &str, s3_endpoint: Option<String>) -> PyResult<String> {
    let (location, options) = open(store, s3_endpoint)?;
    py.detach(|| {
        residency_ingest::inspect::inspect(&location, &options).map_err(|e| residency_error(&e))
    })
}

/// The store at `store` (a folder or `s3://BUCKET/PREFIX`) and how to reach it.
fn open(store: &str, s3_endpoint: Option<String>) -> PyResult<(StoreLocation, ObjectStoreOptions)> {
    let location: StoreLocation = store
        .parse()
        .map_err(|e: LocationError| residency_error(&e))?;
    let options = ObjectStoreOptions::for_location(&location, s3_endpoint)
        .map_err(|e| residency_error(&e))?;
    Ok((location, options))
}

/// Channel `channel`'s region metadata at level `level` (0: the finest) of `store`, read
/// whole: a dict of `cell_shape`, `halo` and `brick_shape` (`z, y, x` tuples and voxels), `min`
/// and `max` (the finest min/max grid with its halo, `float64` arrays `[gz, gy, gx]`, NaN for
/// cells of NaN only), `exact_min` and `exact_max` (the same cells without the halo; `None`
/// in stores of layout 0.1), `histograms` (`uint32` `[bz, by, bx, bins]`, one per brick) and
/// `histogram_edges` (`float64`, the channel's bin edges, shared by every brick and level).
///
/// # Errors
/// `ResidencyError` where the store cannot be read, has no region metadata, or has no such
/// level or channel.
#[pyfunction]
#[pyo3(signature = (store, level = 0, channel = 0, *, s3_endpoint = None))]
fn regions<'py>(
    py: Python<'py>,
    store: &str,
    level: usize,
    channel: usize,
    s3_endpoint: Option<String>,
) -> PyResult<Bound<'py, PyDict>> {
    let (location, options) = open(store, s3_endpoint)?;
    let r = py
        .detach(|| region_arrays::read(&location, &options, level, channel))
        .map_err(|e| residency_error(&e))?;
    let grid = r.grid_shape.map(|n| n as usize);
    let bricks = r.brick_grid.map(|n| n as usize);
    let cells = |values: Vec<f64>| PyArray1::from_vec(py, values).reshape(grid);
    let out = PyDict::new(py);
    let zyx = |v: [u64; 3]| (v[0], v[1], v[2]);
    out.set_item("cell_shape", zyx(r.cell_shape))?;
    out.set_item("halo", r.halo)?;
    out.set_item("brick_shape", zyx(r.brick_shape))?;
    out.set_item("min", cells(r.min)?)?;
    out.set_item("max", cells(r.max)?)?;
    if let Some((lo, hi)) = r.exact {
        out.set_item("exact_min", cells(lo)?)?;
        out.set_item("exact_max", cells(hi)?)?;
    } else {
        out.set_item("exact_min", py.None())?;
        out.set_item("exact_max", py.None())?;
    }
    let histograms =
        PyArray1::from_vec(py, r.histograms).reshape([bricks[0], bricks[1], bricks[2], r.bins])?;
    out.set_item("histograms", histograms)?;
    out.set_item("histogram_edges", PyArray1::from_vec(py, r.edges))?;
    Ok(out)
}

/// `volume` rendered as `viewer render` renders it with the same scene and size: a `uint8`
/// array `[height, width, 3]` of the 8-bit sRGB pixels its PNG holds. `volume` is a store (a
/// folder or `s3://BUCKET/PREFIX`, with `s3_endpoint` as in [`inspect`]) or a `brickserver`
/// URL with `dataset` the dataset's name; `scene` a scene (`schemas/json/scene.schema.json`)
/// as a dict or JSON text, `None` for the volume's default scene. Rendered on the GPU (Mesa's
/// lavapipe where there is none) until no brick is outstanding, or 64 frames.
///
/// # Errors
/// `ResidencyError` with `viewer render`'s message where the volume cannot be opened, the
/// scene is not one of it, or the GPU fails; also for a URL without `dataset`.
#[pyfunction]
#[pyo3(signature = (volume, scene = None, width = 256, height = 256, *, dataset = None, s3_endpoint = None))]
fn render<'py>(
    py: Python<'py>,
    volume: &str,
    scene: Option<Bound<'py, PyAny>>,
    width: u32,
    height: u32,
    dataset: Option<String>,
    s3_endpoint: Option<String>,
) -> PyResult<Bound<'py, PyAny>> {
    let served = volume.starts_with("http://") || volume.starts_with("https://");
    let source = match (served, dataset) {
        (true, Some(dataset)) => rendering::Volume::Served {
            url: volume.to_string(),
            dataset,
        },
        (true, None) => {
            return Err(ResidencyError::new_err(format!(
                "{volume}: a server's URL needs dataset=NAME"
            )));
        }
        (false, Some(_)) => {
            return Err(ResidencyError::new_err(format!(
                "{volume}: dataset= names a dataset of a server; a store is one volume"
            )));
        }
        (false, None) => {
            let (location, options) = open(volume, s3_endpoint)?;
            rendering::Volume::Store(location, options)
        }
    };
    let scene: Option<String> = match scene {
        None => None,
        Some(s) if s.is_instance_of::<pyo3::types::PyString>() => Some(s.extract()?),
        Some(s) => Some(py.import("json")?.call_method1("dumps", (s,))?.extract()?),
    };
    let pixels = py
        .detach(|| rendering::render(&source, scene.as_deref(), width, height))
        .map_err(|e| residency_error(&e))?;
    let image = PyArray1::from_vec(py, pixels).reshape([height as usize, width as usize, 3])?;
    Ok(image.into_any())
}

/// An edge given as one number (a cube) or `(z, y, x)`, as `--chunk 64` or `--chunk 16,64,64`.
fn edge(value: &Bound<'_, PyAny>) -> PyResult<[u64; 3]> {
    if let Ok(n) = value.extract::<u64>() {
        return Ok([n; 3]);
    }
    value.extract::<[u64; 3]>()
}

/// `ingest convert INPUTS -o OUTPUT` in this process: the inputs (TIFF, OME-TIFF, ImageJ
/// files, folders or globs of slices, raw files; each becomes one or more channels, in order)
/// converted into the OME-Zarr store `output` (a folder) with region metadata. The options
/// are `ingest convert`'s flags: `chunk` and `shard` (an edge or `(z, y, x)`), `voxel_size`
/// (`(z, y, x)`), `unit`, `ome_zarr_version` (`"0.5"` or `"0.4"`), `levels`,
/// `channel_names`, `overwrite`, `memory_limit` (bytes), `map_inputs` (false: `--no-mmap`),
/// and for raw inputs `dims` (`(x, y, z)`), `dtype`, `endian`, `header_bytes`. `progress(done, total)` is called as the input is
/// read (bytes). Returns a dict: `output`, `input_bytes`, `planes_in_place` (level-0 planes read
/// where they lie in the input files), `stored_bytes`, `seconds` and `report` (the text
/// `ingest convert` prints).
///
/// # Errors
/// `ResidencyError` with `ingest convert`'s message; an exception `progress` raised, once the
/// conversion has finished.
#[pyfunction]
#[pyo3(signature = (
    inputs, output, *, chunk = None, shard = None, voxel_size = None, unit = None,
    ome_zarr_version = "0.5", levels = None, channel_names = None, overwrite = false,
    memory_limit = None, map_inputs = true, dims = None, dtype = None, endian = "little",
    header_bytes = 0, progress = None
))]
#[allow(clippy::too_many_arguments)]
fn convert<'py>(
    py: Python<'py>,
    inputs: Vec<String>,
    output: std::path::PathBuf,
    chunk: Option<Bound<'py, PyAny>>,
    shard: Option<Bound<'py, PyAny>>,
    voxel_size: Option<[f64; 3]>,
    unit: Option<String>,
    ome_zarr_version: &str,
    levels: Option<usize>,
    channel_names: Option<Vec<String>>,
    overwrite: bool,
    memory_limit: Option<u64>,
    map_inputs: bool,
    dims: Option<[u64; 3]>,
    dtype: Option<String>,
    endian: &str,
    header_bytes: u64,
    progress: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    use residency_ingest::store::OmeZarrVersion;
    let bad = |message: String| ResidencyError::new_err(message);
    if levels == Some(0) {
        return Err(bad("levels must be at least 1".into()));
    }
    let mut options = residency_ingest::ConvertOptions::new(inputs, output);
    options.raw = residency_ingest::source::RawOptions {
        dims,
        format: dtype
            .as_deref()
            .map(str::parse::<residency_schemas::SampleType>)
            .transpose()
            .map_err(|e| residency_error(&e))?,
        big_endian: match endian {
            "little" => false,
            "big" => true,
            other => return Err(bad(format!("endian {other:?}: little or big"))),
        },
        header_bytes,
    };
    options.voxel_size = voxel_size;
    options.unit = unit;
    if let Some(chunk) = &chunk {
        options.brick = edge(chunk)?;
    }
    options.shard = shard.as_ref().map(edge).transpose()?;
    options.version = match ome_zarr_version {
        "0.5" => OmeZarrVersion::V05,
        "0.4" => OmeZarrVersion::V04,
        other => {
            return Err(bad(format!(
                "ome_zarr_version {other:?}: \"0.5\" or \"0.4\""
            )));
        }
    };
    options.levels = levels;
    options.overwrite = overwrite;
    options.channel_names = channel_names.unwrap_or_default();
    options.memory_limit = memory_limit;
    options.map_inputs = map_inputs;
    let failed = std::sync::Arc::new(std::sync::Mutex::new(None));
    options.on_progress = progress.map(|p| conversion::python_progress(p, failed.clone()));
    let summary = py
        .detach(|| residency_ingest::convert(&options))
        .map_err(|e| residency_error(&e))?;
    if let Some(e) = failed
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
        .take()
    {
        return Err(e);
    }
    let out = PyDict::new(py);
    out.set_item("output", summary.output.to_string_lossy().into_owned())?;
    out.set_item("input_bytes", summary.input_bytes)?;
    out.set_item("planes_in_place", summary.planes_in_place)?;
    out.set_item("stored_bytes", summary.stored_bytes)?;
    out.set_item("seconds", summary.seconds)?;
    out.set_item("report", summary.report())?;
    Ok(out)
}

/// `brickserver serve STORES` in this process until closed (`residency.Server` wraps it):
/// `url` is where it listens, as `brickserver` prints it.
#[pyclass(module = "residency._native")]
struct Server {
    running: server::Running,
}

#[pymethods]
impl Server {
    /// Starts serving `stores` (folders or `s3://BUCKET/PREFIX`) on `bind` (`HOST:PORT`, port
    /// 0 for a free one), the web viewer from `viewer_dir`; returns once it listens.
    ///
    /// # Errors
    /// `ResidencyError` with `brickserver serve`'s message.
    #[new]
    #[pyo3(signature = (stores, bind = "127.0.0.1:0", viewer_dir = None, s3_endpoint = None))]
    fn new(
        py: Python<'_>,
        stores: Vec<String>,
        bind: &str,
        viewer_dir: Option<std::path::PathBuf>,
        s3_endpoint: Option<String>,
    ) -> PyResult<Self> {
        let locations = stores
            .iter()
            .map(|s| s.parse::<StoreLocation>())
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| residency_error(&e))?;
        let bind: std::net::SocketAddr = bind
            .parse()
            .map_err(|e| ResidencyError::new_err(format!("--bind {bind}: {e}")))?;
        let running = py
            .detach(|| server::Running::start(&locations, bind, viewer_dir, s3_endpoint))
            .map_err(|e| residency_error(&e))?;
        Ok(Self { running })
    }

    /// The base URL, `http://HOST:PORT`.
    #[getter]
    fn url(&self) -> String {
        format!("http://{}", self.running.address)
    }

    /// Stops serving: open requests finish (for at most 10 s) and the server's threads end.
    fn close(&mut self, py: Python<'_>) {
        py.detach(|| self.running.stop());
    }
}

/// The module: the functions above, `ResidencyError` and `__version__`.
#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("ResidencyError", m.py().get_type::<ResidencyError>())?;
    m.add_function(wrap_pyfunction!(convert, m)?)?;
    m.add_function(wrap_pyfunction!(inspect, m)?)?;
    m.add_function(wrap_pyfunction!(regions, m)?)?;
    m.add_function(wrap_pyfunction!(render, m)?)?;
    m.add_class::<Server>()?;
    Ok(())
}
