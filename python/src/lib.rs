//! `residency._native`: the Rust libraries as a CPython extension module, wrapped by the
//! `residency` package (`python/residency/__init__.py`). Errors are `residency.ResidencyError`
//! with the message the command line prints for the same failure.

use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;
use residency_store::location::{ObjectStoreOptions, StoreLocation};

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
    let location: StoreLocation = store
        .parse()
        .map_err(|e: residency_store::location::LocationError| residency_error(&e))?;
    py.detach(|| {
        let options = ObjectStoreOptions::for_location(&location, s3_endpoint)
            .map_err(|e| residency_error(&e))?;
        residency_ingest::inspect::inspect(&location, &options).map_err(|e| residency_error(&e))
    })
}

/// The module: the functions above, `ResidencyError` and `__version__`.
#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("ResidencyError", m.py().get_type::<ResidencyError>())?;
    m.add_function(wrap_pyfunction!(inspect, m)?)?;
    Ok(())
}
