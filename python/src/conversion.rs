//! `residency.convert(...)`'s progress: a Python callable told each step of `ingest
//! convert`'s progress (`ingest`'s [`ProgressCallback`]).

use std::sync::{Arc, Mutex};

use pyo3::prelude::*;
use residency_ingest::progress::ProgressCallback;

/// A [`ProgressCallback`] calling `callback(done, total)` (bytes of input read so far, and the
/// pass's total) with the GIL held; the first exception it raises is kept in `failed` (the
/// conversion goes on; the caller raises it once the conversion has finished).
pub fn python_progress(callback: Py<PyAny>, failed: Arc<Mutex<Option<PyErr>>>) -> ProgressCallback {
    ProgressCallback(Arc::new(move |done, total| {
        Python::attach(|py| {
            if let Err(e) = callback.call1(py, (done, total)) {
                failed
                    .lock()
                    .unwrap_or_else(std::sync::PoisonError::into_inner)
                    .get_or_insert(e);
            }
        });
    }))
}
