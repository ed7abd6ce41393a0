//! [`VdiError`]: why a VDI file cannot be read, or an image cannot be written.

use super::{MAX_HEADER_BYTES, MAX_SUPERSEGMENTS, MAX_VDI_PIXELS, MAX_VDI_SLOTS, VDI_VERSION};

/// A VDI file or image that cannot be read or written. Every message starts with the file
/// (name or URL) at fault, or with `VDI to encode` for an image that
/// [`VolumetricDepthImage::encode`](super::VolumetricDepthImage::encode) refuses.
#[derive(Debug, thiserror::Error)]
pub enum VdiError {
    /// The input does not start with [`VDI_MAGIC`](super::VDI_MAGIC).
    #[error("{file}: not a VDI (bad magic)")]
    BadMagic {
        /// The file.
        file: String,
    },
    /// The input ends before something it announces.
    #[error("{file}: truncated: the {what} needs {needed} bytes, only {available} remain")]
    Truncated {
        /// The file.
        file: String,
        /// What was being read.
        what: String,
        /// Bytes it needs.
        needed: u64,
        /// Bytes left in the input.
        available: u64,
    },
    /// The header is longer than [`MAX_HEADER_BYTES`].
    #[error("{file}: the header is {length} bytes long, more than the {MAX_HEADER_BYTES} allowed")]
    HeaderTooLong {
        /// The file.
        file: String,
        /// Its length.
        length: u64,
    },
    /// The header is not the JSON of a [`VdiHeader`](super::VdiHeader).
    #[error("{file}: bad VDI header: {source}")]
    BadHeader {
        /// The file.
        file: String,
        /// What the JSON parser said.
        #[source]
        source: serde_json::Error,
    },
    /// The header's version is not [`VDI_VERSION`].
    #[error("{file}: VDI version {version} is not supported (this build reads {VDI_VERSION})")]
    Version {
        /// The file.
        file: String,
        /// The version it claims.
        version: u32,
    },
    /// `width·height` is 0 or above [`MAX_VDI_PIXELS`].
    #[error("{file}: a VDI of {width}×{height} pixels: it must have 1 to {MAX_VDI_PIXELS} pixels")]
    Pixels {
        /// The file.
        file: String,
        /// Width it claims.
        width: u32,
        /// Height it claims.
        height: u32,
    },
    /// N_S is 0 or above [`MAX_SUPERSEGMENTS`].
    #[error("{file}: {supersegments} supersegments per list: a VDI has 1 to {MAX_SUPERSEGMENTS}")]
    Supersegments {
        /// The file.
        file: String,
        /// N_S it claims.
        supersegments: u32,
    },
    /// `width·height·N_S` is above [`MAX_VDI_SLOTS`].
    #[error(
        "{file}: {width}×{height} lists of {supersegments} supersegments are {slots} slots, more \
         than the {MAX_VDI_SLOTS} a VDI may hold"
    )]
    Slots {
        /// The file.
        file: String,
        /// Width it claims.
        width: u32,
        /// Height it claims.
        height: u32,
        /// N_S it claims.
        supersegments: u32,
        /// Their product.
        slots: u64,
    },
    /// The scene hash is not 16 lowercase hex digits.
    #[error("{file}: scene hash {hash:?} is not 16 lowercase hex digits")]
    SceneHash {
        /// The file.
        file: String,
        /// The hash it claims.
        hash: String,
    },
    /// A number of the header is out of its range.
    #[error("{file}: header field {field} {problem}")]
    HeaderField {
        /// The file.
        file: String,
        /// The field (or fields).
        field: &'static str,
        /// What is wrong with it.
        problem: &'static str,
    },
    /// An in-memory array's length does not match the header (only from `encode`).
    #[error("{file}: {array} has {length} entries, the header and counts imply {expected}")]
    Length {
        /// The file.
        file: String,
        /// The array: `counts`, `colour` or `depth`.
        array: &'static str,
        /// Its length.
        length: usize,
        /// The length the header (counts: one per list) or the counts (colour, depth: their
        /// sum) imply.
        expected: u64,
    },
    /// An uncompressed plane's stored length differs from what the header and counts imply.
    #[error(
        "{file}: the {plane} plane holds {stored} bytes, the header and counts imply {expected}"
    )]
    PlaneSize {
        /// The file.
        file: String,
        /// `counts`, `colour` or `depth`.
        plane: &'static str,
        /// Bytes stored.
        stored: u64,
        /// Bytes implied.
        expected: u64,
    },
    /// An LZ4 or zstd plane's announced raw length differs from what the header and counts
    /// imply (checked before decompressing).
    #[error(
        "{file}: the {plane} plane announces {announced} bytes decompressed, the header and \
         counts imply {expected}"
    )]
    AnnouncedSize {
        /// The file.
        file: String,
        /// `counts`, `colour` or `depth`.
        plane: &'static str,
        /// Raw length the LZ4 prefix or the zstd frame header announces.
        announced: u64,
        /// Bytes implied.
        expected: u64,
    },
    /// An LZ4 plane is not a valid LZ4 block.
    #[error("{file}: the {plane} plane does not decompress")]
    Lz4 {
        /// The file.
        file: String,
        /// `counts`, `colour` or `depth`.
        plane: &'static str,
        /// What the LZ4 decoder said.
        #[source]
        source: lz4_flex::block::DecompressError,
    },
    /// A zstd plane is not exactly one zstd frame that announces its decompressed size
    /// (checked before decompressing).
    #[error("{file}: the {plane} plane is not a zstd frame of known size: {problem}")]
    ZstdFrame {
        /// The file.
        file: String,
        /// `counts`, `colour` or `depth`.
        plane: &'static str,
        /// What is wrong with the frame.
        problem: &'static str,
    },
    /// A zstd plane's frame does not decompress.
    #[error("{file}: the {plane} plane does not decompress")]
    Zstd {
        /// The file.
        file: String,
        /// `counts`, `colour` or `depth`.
        plane: &'static str,
        /// What the zstd decoder said.
        #[source]
        source: std::io::Error,
    },
    /// An LZ4 or zstd plane decompresses to fewer bytes than it announces.
    #[error(
        "{file}: the {plane} plane decompresses to {actual} bytes, not the {expected} it announces"
    )]
    ShortPlane {
        /// The file.
        file: String,
        /// `counts`, `colour` or `depth`.
        plane: &'static str,
        /// Bytes it gave.
        actual: u64,
        /// Bytes announced.
        expected: u64,
    },
    /// A list holds more supersegments than N_S.
    #[error(
        "{file}: list ({x}, {y}) has {count} supersegments, more than the header's {supersegments}"
    )]
    Count {
        /// The file.
        file: String,
        /// Column of the list.
        x: u32,
        /// Row of the list.
        y: u32,
        /// Its count.
        count: u8,
        /// N_S.
        supersegments: u32,
    },
    /// Bytes follow the depth plane.
    #[error("{file}: {extra} bytes follow the depth plane")]
    Trailing {
        /// The file.
        file: String,
        /// How many.
        extra: u64,
    },
    /// A used slot holds NaN or an infinity (its colour as a half float: an `f32` colour of
    /// 65520 or more is infinite there).
    #[error("{file}: list ({x}, {y}) supersegment {slot} has a non-finite {what}")]
    NonFinite {
        /// The file.
        file: String,
        /// Column of the list.
        x: u32,
        /// Row of the list.
        y: u32,
        /// Index of the supersegment in its list.
        slot: u32,
        /// `colour` or `depth`.
        what: &'static str,
    },
    /// A used slot's colour is below 0 or its opacity outside `[0, 1]` (a premultiplied
    /// colour may pass 1: channels mix additively).
    #[error(
        "{file}: list ({x}, {y}) supersegment {slot} has colour and opacity {colour:?}: a colour \
         below 0 or an opacity outside [0, 1]"
    )]
    ColourRange {
        /// The file.
        file: String,
        /// Column of the list.
        x: u32,
        /// Row of the list.
        y: u32,
        /// Index of the supersegment in its list.
        slot: u32,
        /// Its `[r, g, b, a]`.
        colour: [f32; 4],
    },
    /// A used slot's depths are not `0 ≤ front ≤ back`.
    #[error(
        "{file}: list ({x}, {y}) supersegment {slot} has front {front} and back {back}, not 0 ≤ \
         front ≤ back"
    )]
    DepthOrder {
        /// The file.
        file: String,
        /// Column of the list.
        x: u32,
        /// Row of the list.
        y: u32,
        /// Index of the supersegment in its list.
        slot: u32,
        /// Front distance.
        front: f32,
        /// Back distance.
        back: f32,
    },
    /// A used slot begins before the one before it in its list ends: a list's supersegments
    /// follow each other front to back, which readers rely on to find where a ray is.
    #[error(
        "{file}: list ({x}, {y}) supersegment {slot} begins at {front}, before supersegment {} \
         ends at {previous_back}: a list's supersegments must follow each other front to back",
        slot - 1
    )]
    ListOrder {
        /// The file.
        file: String,
        /// Column of the list.
        x: u32,
        /// Row of the list.
        y: u32,
        /// Index of the supersegment in its list (at least 1).
        slot: u32,
        /// Its front distance.
        front: f32,
        /// The back distance of the supersegment before it.
        previous_back: f32,
    },
}
