//! Storage for Residency's stores: where a store lives and how its pyramid is read.
//!
//! The format itself (sample types, OME-Zarr and Zarr metadata, region metadata, wire formats)
//! is `residency-schemas`, which does no I/O and builds for the browser. This crate adds what
//! touches storage:
//! - [`location`]: a store's location (a local folder, or a prefix in an S3-compatible bucket)
//!   opened as one zarrs storage, and publishing, listing and downloading object-store stores;
//! - [`at_once`]: blocking reads side by side, for one-time loads over an object store;
//! - [`aws_profile`]: the AWS shared configuration profiles that `object_store` does not read;
//! - [`failure`]: an object store that failed a request, told apart from one not reached,
//!   through whatever layers carry it;
//! - [`pyramid`]: the pyramid reader, bricks and metadata through zarrs' codecs over any
//!   zarrs storage;
//! - [`ranged`]: an object store read by zarrs with one ranged `GET` per read (no `HEAD`);
//! - [`region_array`]: a region-metadata array read whole or by channel, as `f64` values.

#[cfg(feature = "mimalloc")]
pub mod allocator;
pub mod at_once;
pub mod aws_profile;
pub mod failure;
pub mod location;
pub mod pyramid;
pub mod ranged;
pub mod region_array;
