//! Known panics in dependencies, already fixed upstream, that would otherwise stop every run
//! of a target at the first input reaching them.
//!
//! libfuzzer-sys aborts on any panic. [`guarded`] runs a closure so that a panic at one of the
//! [`KNOWN`] places unwinds into it and is counted as a refused input instead; any other panic
//! still aborts and is reported. With `RESIDENCY_FUZZ_STRICT=1` nothing is tolerated.
//!
//! Each entry names the dependency's source file and line as the panic reports them: after an
//! upgrade the paths no longer match, so a fixed entry is inert and a still-present bug shows
//! up again. `docs/fuzzing.md` lists them; the panics fixed upstream (tiff 0.11) have
//! regression tests in `ingest/tests/integration/fuzz_regressions.rs`.

use std::cell::Cell;
use std::panic::{AssertUnwindSafe, PanicHookInfo};
use std::sync::Once;

/// `(path suffix, line)` of the panics tolerated.
pub const KNOWN: &[(&str, u32)] = &[
    // tiff 0.11.3 (and 0.10.3): `(strips per plane) * planes` overflows u32 for a planar page
    // with huge SamplesPerPixel. Only builds with overflow checks (this one) panic; release
    // builds wrap, and the count check then refuses the page as inconsistent. Not yet
    // reported upstream.
    ("tiff-0.11.3/src/decoder/image.rs", 336),
];

thread_local! {
    static KNOWN_PANIC: Cell<bool> = const { Cell::new(false) };
}

fn is_known(info: &PanicHookInfo<'_>) -> bool {
    info.location().is_some_and(|l| {
        KNOWN
            .iter()
            .any(|&(file, line)| l.file().ends_with(file) && l.line() == line)
    })
}

fn install() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        if std::env::var_os("RESIDENCY_FUZZ_STRICT").is_some_and(|v| v == "1") {
            return;
        }
        // libfuzzer-sys's hook (print, then abort) is in place by now: wrap it.
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if is_known(info) {
                KNOWN_PANIC.with(|k| k.set(true));
                return;
            }
            previous(info);
        }));
    });
}

/// Runs `f`; `None` if it panicked at a [`KNOWN`] place.
pub fn guarded<R>(f: impl FnOnce() -> R) -> Option<R> {
    install();
    KNOWN_PANIC.with(|k| k.set(false));
    match std::panic::catch_unwind(AssertUnwindSafe(f)) {
        Ok(r) => Some(r),
        Err(payload) => {
            if KNOWN_PANIC.with(|k| k.get()) {
                None
            } else {
                std::panic::resume_unwind(payload)
            }
        }
    }
}
