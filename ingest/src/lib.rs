//! `residency-ingest`: converts raw and TIFF stacks into LZ4-compressed OME-Zarr multiscale
//! pyramids, and writes min/max and histogram region metadata in the same streaming pass.
//!
//! The modules, in the order data flows through them:
//! - [`source`]: reading inputs plane by plane (TIFF, OME-TIFF, ImageJ, slice folders, raw);
//! - [`sample_format`]: the voxel types, their exact arithmetic, and the planes sources fill;
//! - `pyramid`: the anisotropy-aware level plan;
//! - `regions`: min/max cells, brick histograms, channel statistics;
//! - [`region_writer`]: writing them as Zarr arrays and the `residency` document as the pass
//!   goes, with `region_scratch` holding on disk what cannot be written yet;
//! - [`convert`](mod@convert): the streaming pass itself, in [`columns`] where planes are too
//!   large for the memory limit; [`index`] runs the same analysis on an existing store;
//!   [`partition`]: a pass split into partitions and finished by `finalize`;
//! - [`store`] and `ome`: Zarr and OME-Zarr metadata, and atomic writes;
//! - [`synthetic`]: the built-in synthetic samples (light-sheet fluorescence, sparse CT,
//!   dense simulation, multiplexed immunofluorescence);
//! - [`inspect`]: the `ingest inspect` report;
//! - [`progress`]: the byte-counting progress bar of conversions and uploads;
//! - [`memory`]: the machine's memory, for refusing work that cannot fit before allocating.
//!
//! Modules and items that only other modules of this crate use are `pub(crate)`; the
//! `ingest` binary (behind the default `cli` feature) uses the public ones.
//!
//! Errors are `thiserror` enums, one per module ([`source::SourceError`],
//! [`store::StoreError`], [`region_writer::RegionWriteError`], [`convert::ConvertError`],
//! [`partition::HandoffError`], [`index::IndexError`], [`inspect::InspectError`],
//! [`synthetic::SampleError`]): each message names the file, option or array at fault, and
//! the underlying error is its `source()`, so the binary's `error: {e:#}` prints the whole
//! chain once.

pub mod columns;
pub mod convert;
pub mod index;
pub mod inspect;
pub mod memory;
pub(crate) mod ome;
pub mod partition;
pub mod progress;
pub(crate) mod pyramid;
pub(crate) mod region_scratch;
pub mod region_writer;
pub(crate) mod regions;
pub mod sample_format;
pub mod source;
pub mod store;
pub mod synthetic;

pub use convert::{ConvertOptions, ConvertSummary, convert, convert_partition, finalize};
