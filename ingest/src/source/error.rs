//! Why an input cannot be opened or read: [`SourceError`], and the descriptions it holds of
//! a refused TIFF directory ([`TiffDirectoryError`]) and of a plane a page claims
//! ([`PlaneClaim`]).

use std::fmt;
use std::io;
use std::path::PathBuf;

use super::tiff_metadata::OmeXmlError;
use crate::sample_format::SampleType;

/// An input that cannot be opened or read. Every message starts with the input (the argument
/// as given, or the file at fault) and says what is wrong with it; the underlying error, when
/// there is one, is the [`source`](std::error::Error::source).
#[derive(Debug, thiserror::Error)]
pub enum SourceError {
    /// The input names nothing.
    #[error("{input}: no such file or directory")]
    NotFound {
        /// The argument as given.
        input: String,
    },
    /// A file cannot be opened (or its size read).
    #[error("{}: cannot open", path.display())]
    Open {
        /// The file.
        path: PathBuf,
        /// What the file system said.
        #[source]
        source: io::Error,
    },
    /// A file without an extension too short to hold a TIFF header.
    #[error("{}: file too short to identify", path.display())]
    TooShort {
        /// The file.
        path: PathBuf,
        /// What reading said.
        #[source]
        source: io::Error,
    },
    /// A file that is neither TIFF nor recognisably raw.
    #[error(
        "{input}: unknown input kind: expected a TIFF file, a folder or glob of TIFF slices, or a raw file (name_XxYxZ_dtype.raw, or --dims/--dtype)"
    )]
    UnknownKind {
        /// The argument as given.
        input: String,
    },

    // TIFF files.
    /// The decoder cannot read the file's header or first directory.
    #[error("{}: not a readable TIFF file", path.display())]
    NotTiff {
        /// The file.
        path: PathBuf,
        /// What the decoder said.
        #[source]
        source: TiffDirectoryError,
    },
    /// A page's directory cannot be read.
    #[error("{}: cannot read the directory of page {page} (truncated or corrupt TIFF)", path.display())]
    Directory {
        /// The file.
        path: PathBuf,
        /// The page.
        page: u64,
        /// What the decoder said.
        #[source]
        source: TiffDirectoryError,
    },
    /// A page's strip or tile tags cannot be read.
    #[error("{}: cannot read the strips of page {page} (truncated or corrupt TIFF)", path.display())]
    Strips {
        /// The file.
        path: PathBuf,
        /// The page.
        page: u64,
        /// What the decoder said.
        #[source]
        source: TiffDirectoryError,
    },
    /// The first page's size cannot be read.
    #[error("{}: cannot read the image size", path.display())]
    ImageSize {
        /// The file.
        path: PathBuf,
        /// What the decoder said.
        #[source]
        source: ::tiff::TiffError,
    },
    /// A page's colour type cannot be read.
    #[error("{}: cannot read the pixel layout", path.display())]
    PixelLayout {
        /// The file.
        path: PathBuf,
        /// What the decoder said.
        #[source]
        source: ::tiff::TiffError,
    },
    /// A colour type other than grey, grey and alpha, RGB, RGBA or multiband.
    #[error("{}: unsupported sample format: colour type {colour:?}", path.display())]
    UnsupportedColour {
        /// The file.
        path: PathBuf,
        /// The colour type.
        colour: ::tiff::ColorType,
    },
    /// A sample width and kind that is not one of the [`SampleType`]s.
    #[error(
        "{}: unsupported sample format: {bits}-bit {kind} (supported: 8/16/32-bit unsigned, 16/32-bit signed, 32-bit float)",
        path.display()
    )]
    UnsupportedSamples {
        /// The file.
        path: PathBuf,
        /// Bits per sample.
        bits: u8,
        /// The `SampleFormat` in words (`unsigned integer`, ...).
        kind: &'static str,
    },
    /// Several samples per pixel stored in separate planes.
    #[error(
        "{}: unsupported sample format: planar-separate pages with {samples} samples per pixel",
        path.display()
    )]
    PlanarSeparate {
        /// The file.
        path: PathBuf,
        /// Samples per pixel.
        samples: usize,
    },
    /// The OME-XML of an OME-TIFF is unusable.
    #[error("{}: OME-TIFF", path.display())]
    OmeTiff {
        /// The file.
        path: PathBuf,
        /// What is wrong with the OME-XML.
        #[source]
        source: OmeXmlError,
    },
    /// A series of several time points.
    #[error(
        "{}: has {time_points} time points; ingest converts one time point per store (split the series first)",
        path.display()
    )]
    TimePoints {
        /// The file.
        path: PathBuf,
        /// Time points the metadata describes.
        time_points: u64,
    },
    /// Metadata describing no z plane.
    #[error("{}: metadata describes 0 z planes (corrupt metadata)", path.display())]
    NoPlanes {
        /// The file.
        path: PathBuf,
    },
    /// Fewer pages than the metadata describes.
    #[error(
        "{}: metadata describes {needed} pages ({channels} channels x {depth} z) but the file has only {pages} (truncated?)",
        path.display()
    )]
    MissingPages {
        /// The file.
        path: PathBuf,
        /// Pages described.
        needed: u128,
        /// Channel planes described.
        channels: usize,
        /// Z planes described.
        depth: u64,
        /// Pages in the file.
        pages: u64,
    },
    /// A page that cannot be found.
    #[error("{}: cannot find page {page} (truncated or corrupt TIFF)", path.display())]
    Seek {
        /// The file.
        path: PathBuf,
        /// The page.
        page: u64,
        /// What the decoder said.
        #[source]
        source: ::tiff::TiffError,
    },
    /// A page whose size differs from the first page's.
    #[error(
        "{}: page {page} is {width}x{height} pixels but page 0 is {}x{}",
        path.display(), expected[1], expected[0]
    )]
    PageSize {
        /// The file.
        path: PathBuf,
        /// The page.
        page: u64,
        /// Its width.
        width: u32,
        /// Its height.
        height: u32,
        /// Height and width of page 0.
        expected: [u64; 2],
    },
    /// A page whose sample format differs from the first page's.
    #[error(
        "{}: page {page} holds {samples} x {format} samples per pixel but page 0 holds {expected_samples} x {expected_format}",
        path.display()
    )]
    PageFormat {
        /// The file.
        path: PathBuf,
        /// The page.
        page: u64,
        /// Its samples per pixel.
        samples: usize,
        /// Its sample format.
        format: SampleType,
        /// Samples per pixel of page 0.
        expected_samples: usize,
        /// Sample format of page 0.
        expected_format: SampleType,
    },
    /// A page that cannot be decoded.
    #[error("{}: cannot decode page {page} (truncated or corrupt TIFF)", path.display())]
    Decode {
        /// The file.
        path: PathBuf,
        /// The page.
        page: u64,
        /// What the decoder said.
        #[source]
        source: ::tiff::TiffError,
    },
    /// Any other refusal of the decoder, in its own words.
    #[error(transparent)]
    Tiff(::tiff::TiffError),

    // What a page claims (see `tiff_claims`).
    /// A strip or tile that runs past the end of the file.
    #[error(
        "{}: page {page}: {chunk} {index} claims {count} bytes at offset {offset} but the file has only {file_len} bytes (truncated or corrupt TIFF)",
        path.display()
    )]
    ChunkOutsideFile {
        /// The file.
        path: PathBuf,
        /// The page.
        page: u64,
        /// `strip` or `tile`.
        chunk: &'static str,
        /// Which strip or tile.
        index: usize,
        /// Its byte count.
        count: u64,
        /// Its offset.
        offset: u64,
        /// Length of the file.
        file_len: u64,
    },
    /// CCITT Group 4, which encodes 1-bit (bilevel) images only, and no sample type here is
    /// 1-bit.
    #[error(
        "{}: page {page}: CCITT Group 4 compression encodes 1-bit (bilevel) images, and {bits}-bit samples are not 1-bit (unsupported)",
        path.display()
    )]
    BilevelCodec {
        /// The file.
        path: PathBuf,
        /// The page.
        page: u64,
        /// Bits per sample the page claims.
        bits: usize,
    },
    /// A codec the decoder does not have.
    #[error(
        "{}: page {page}: unsupported compression {compression} (supported: none, LZW, Deflate, PackBits, JPEG)",
        path.display()
    )]
    UnsupportedCompression {
        /// The file.
        path: PathBuf,
        /// The page.
        page: u64,
        /// The TIFF `Compression` code.
        compression: u16,
    },
    /// An uncompressed plane larger than the whole file.
    #[error(
        "{plane}, more than the whole file ({file_len} bytes) although it is stored uncompressed (corrupt TIFF)"
    )]
    PlaneOverFile {
        /// The plane claimed.
        plane: Box<PlaneClaim>,
        /// Length of the file.
        file_len: u64,
    },
    /// A compressed plane larger than its strips or tiles can decode to.
    #[error(
        "{plane}, more than its {chunks} {codec}-compressed {chunk}{} of {compressed} bytes can decode to (at most {most} bytes; corrupt TIFF)",
        if *chunks == 1 { "" } else { "s" }
    )]
    PlaneOverCodec {
        /// The plane claimed.
        plane: Box<PlaneClaim>,
        /// Number of strips or tiles.
        chunks: usize,
        /// The codec's name.
        codec: String,
        /// `strip` or `tile`.
        chunk: &'static str,
        /// Their bytes together.
        compressed: u128,
        /// The most they can decode to.
        most: u128,
    },
    /// A plane larger than the machine's physical memory.
    #[error("{plane}, more than this machine's memory ({memory} bytes)")]
    PlaneOverMemory {
        /// The plane claimed.
        plane: Box<PlaneClaim>,
        /// Physical memory in bytes.
        memory: u64,
    },

    // Folders and globs of TIFF slices.
    /// A folder that cannot be listed.
    #[error("{}: cannot list folder", path.display())]
    ListFolder {
        /// The folder.
        path: PathBuf,
        /// What the file system said.
        #[source]
        source: io::Error,
    },
    /// A glob pattern that does not parse.
    #[error("{pattern}: invalid glob pattern")]
    BadGlob {
        /// The pattern.
        pattern: String,
        /// What the glob parser said.
        #[source]
        source: glob::PatternError,
    },
    /// A folder or glob without TIFF files.
    #[error("{}: no TIFF slices found", path.display())]
    NoSlices {
        /// The folder or pattern.
        path: PathBuf,
    },
    /// A slice whose size differs from the first slice's.
    #[error(
        "{}: slice is {width}x{height} pixels but {} is {}x{}",
        path.display(), first.display(), expected[1], expected[0]
    )]
    SliceSize {
        /// The slice.
        path: PathBuf,
        /// Its width.
        width: u32,
        /// Its height.
        height: u32,
        /// The first slice.
        first: PathBuf,
        /// Height and width of the first slice.
        expected: [u64; 2],
    },
    /// A slice whose sample format differs from the first slice's.
    #[error(
        "{}: slice holds {samples} x {format} samples but {} holds {expected_samples} x {expected_format}",
        path.display(), first.display()
    )]
    SliceFormat {
        /// The slice.
        path: PathBuf,
        /// Its samples per pixel.
        samples: usize,
        /// Its sample format.
        format: SampleType,
        /// The first slice.
        first: PathBuf,
        /// Samples per pixel of the first slice.
        expected_samples: usize,
        /// Sample format of the first slice.
        expected_format: SampleType,
    },

    // Raw files.
    /// A raw file without `--dims` or dimensions in its name.
    #[error(
        "{}: raw input needs --dims X,Y,Z (or a name like name_XxYxZ_uint8.raw)",
        path.display()
    )]
    RawNeedsDims {
        /// The file.
        path: PathBuf,
    },
    /// A raw file without `--dtype` or a sample type in its name.
    #[error(
        "{}: raw input needs --dtype (or a name like name_XxYxZ_uint8.raw)",
        path.display()
    )]
    RawNeedsType {
        /// The file.
        path: PathBuf,
    },
    /// A raw file whose size cannot be read.
    #[error("{}: cannot stat", path.display())]
    Stat {
        /// The file.
        path: PathBuf,
        /// What the file system said.
        #[source]
        source: io::Error,
    },
    /// `--dims` with a zero extent.
    #[error(
        "{}: --dims {},{},{} has an empty axis; each needs at least one voxel",
        path.display(), dims[0], dims[1], dims[2]
    )]
    RawEmptyAxis {
        /// The file.
        path: PathBuf,
        /// `--dims`, `x, y, z`.
        dims: [u64; 3],
    },
    /// A layout of more than 2^64 bytes.
    #[error(
        "{}: --dims {},{},{} of {format} with a {header_bytes}-byte header is more than 2^64 bytes",
        path.display(), dims[0], dims[1], dims[2]
    )]
    RawTooLarge {
        /// The file.
        path: PathBuf,
        /// `--dims`, `x, y, z`.
        dims: [u64; 3],
        /// The sample type.
        format: SampleType,
        /// `--header-bytes`.
        header_bytes: u64,
    },
    /// A raw file whose size does not match its layout.
    #[error(
        "{}: raw file is {actual} bytes, but --dims {},{},{} of {format} with a {header_bytes}-byte header need {expected} bytes",
        path.display(), dims[0], dims[1], dims[2]
    )]
    RawSize {
        /// The file.
        path: PathBuf,
        /// Its size.
        actual: u64,
        /// `--dims`, `x, y, z`.
        dims: [u64; 3],
        /// The sample type.
        format: SampleType,
        /// `--header-bytes`.
        header_bytes: u64,
        /// The size the layout needs.
        expected: u64,
    },
    /// A plane of a raw file that cannot be read.
    #[error("{}: cannot read plane z={z}", path.display())]
    ReadPlane {
        /// The file.
        path: PathBuf,
        /// The plane.
        z: u64,
        /// What the file system said.
        #[source]
        source: io::Error,
    },
}

/// Why the decoder could not read a page's directory (its tags): its own words, except for a
/// refused value list, where the `tiff` crate's ("decoder limits exceeded") do not say what
/// was wrong with the file.
#[derive(Debug, thiserror::Error)]
pub enum TiffDirectoryError {
    /// A value list longer than the file could hold (the decoder's limits).
    #[error("a directory entry claims more values than the file holds (corrupt TIFF)")]
    TooManyValues,
    /// Anything else the decoder refused.
    #[error(transparent)]
    Decoder(::tiff::TiffError),
}

impl From<::tiff::TiffError> for TiffDirectoryError {
    fn from(error: ::tiff::TiffError) -> Self {
        match error {
            ::tiff::TiffError::LimitsExceeded => Self::TooManyValues,
            other => Self::Decoder(other),
        }
    }
}

/// The plane a page claims, as the messages of [`SourceError`] name it:
/// `f.tif: page 3: plane 100×10 of uint16 needs 2000 bytes`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PlaneClaim {
    /// The TIFF file.
    pub path: PathBuf,
    /// The page, from 0.
    pub page: u64,
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Samples per pixel.
    pub samples: usize,
    /// Sample format.
    pub format: SampleType,
    /// Bytes of the decoded plane.
    pub bytes: u128,
}

impl fmt::Display for PlaneClaim {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}: page {}: plane {}×{}",
            self.path.display(),
            self.page,
            self.width,
            self.height
        )?;
        if self.samples > 1 {
            write!(f, "×{}", self.samples)?;
        }
        write!(f, " of {} needs {} bytes", self.format, self.bytes)
    }
}
