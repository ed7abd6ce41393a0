//! The `ingest` command line.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, Result, bail};
use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};
use clap::{Parser, Subcommand, ValueEnum};
use residency_ingest::convert::{ConvertOptions, convert};
use residency_ingest::partition::{HANDOFF_FOLDER, Partition};
use residency_ingest::progress::bytes_bar;
use residency_ingest::sample_format::SampleType;
use residency_ingest::source::RawOptions;
use residency_ingest::store::{OmeZarrVersion, directory_bytes, partial_path};
use residency_ingest::synthetic::{SampleKind, SampleSpec, write_samples};
use residency_ingest::{convert_partition, finalize};
use residency_store::location::{ObjectStoreOptions, StoreLocation};
use strum::VariantArray;

/// mimalloc keeps freed chunk and slab buffers for reuse instead of returning them to the
/// kernel, which the system allocator does for every large buffer (measured: most of the
/// conversion's time went to page faults without it).
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

/// mimalloc gives freed memory back a second after its last use (the next slab's buffers
/// reuse it before then) and commits arenas page by page, so that the peak RSS stays within
/// `--memory-limit` (see `residency_store::allocator`); set before `main`.
#[used]
#[cfg_attr(target_os = "linux", unsafe(link_section = ".init_array"))]
static RETURN_FREED_MEMORY: extern "C" fn() =
    residency_store::allocator::return_freed_memory_for_converting;

#[derive(Parser)]
#[command(
    name = "ingest",
    version,
    about = "Convert raw and TIFF stacks into LZ4-compressed OME-Zarr pyramids with region metadata"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Clone, Copy, ValueEnum)]
enum Version {
    #[value(name = "0.5")]
    V05,
    #[value(name = "0.4")]
    V04,
}

/// The `--kind` values: every [`SampleKind`] by name, each with its line of `--help`.
fn sample_kinds() -> impl TypedValueParser<Value = SampleKind> {
    let values = SampleKind::VARIANTS
        .iter()
        .map(|&kind| PossibleValue::new(<&'static str>::from(kind)).help(kind_help(kind)));
    PossibleValuesParser::new(values).try_map(|name| name.parse::<SampleKind>())
}

/// What `ingest sample --help` says of `kind`: its channels, their types and its default
/// extent.
fn kind_help(kind: SampleKind) -> &'static str {
    match kind {
        SampleKind::Fluorescence => {
            "Light-sheet fluorescence: nuclei (uint16), membranes, filaments (uint8); 96,256,256"
        }
        SampleKind::Sparse => {
            "Micro-CT of a coiled skeleton, mostly exactly 0 (uint16, 1 channel); 256,256,256"
        }
        SampleKind::Dense => {
            "Mixing fluids filling the volume, no region constant (float32, 1 channel); \
             256,256,256"
        }
        SampleKind::Mixing => {
            "Mixing fluids, pure (constant) outside the mixing layer (float32, 1 channel); \
             256,256,256"
        }
        SampleKind::Cycif => {
            "Multiplexed immunofluorescence of a thin section (uint16, 16 markers); 24,256,256"
        }
    }
}

#[derive(Clone, Copy, ValueEnum)]
enum Endian {
    Little,
    Big,
}

#[derive(Subcommand)]
#[allow(clippy::large_enum_variant)]
enum Command {
    /// Convert one or more inputs (each becomes one or more channels, in order) to OME-Zarr.
    Convert {
        /// TIFF / OME-TIFF / ImageJ files, folders or globs of TIFF slices, or raw files.
        #[arg(required = true)]
        inputs: Vec<String>,
        /// Output store, e.g. `out.ome.zarr`, or s3://BUCKET/PREFIX (converted in a local
        /// temporary folder, then uploaded with the root metadata last).
        #[arg(short, long)]
        output: StoreLocation,
        /// Endpoint URL of an S3-compatible server that is not AWS, for an s3:// output
        /// (default: AWS_ENDPOINT_URL, else AWS).
        #[arg(long, value_name = "URL")]
        s3_endpoint: Option<String>,
        /// Raw inputs: extent X,Y,Z in voxels (not needed for name_XxYxZ_dtype.raw).
        #[arg(long, value_parser = parse_triple_u64)]
        dims: Option<[u64; 3]>,
        /// Raw inputs: sample type (uint8, uint16, int16, uint32, int32, float32).
        #[arg(long)]
        dtype: Option<String>,
        /// Raw inputs: byte order.
        #[arg(long, value_enum, default_value = "little")]
        endian: Endian,
        /// Raw inputs: bytes to skip at the start of the file.
        #[arg(long, default_value_t = 0)]
        header_bytes: u64,
        /// Physical voxel size Z,Y,X, overriding the input metadata.
        #[arg(long, value_parser = parse_triple_f64)]
        voxel_size: Option<[f64; 3]>,
        /// Physical unit of the voxel size (e.g. micrometer, nanometer).
        #[arg(long)]
        unit: Option<String>,
        /// Brick (chunk) edge in voxels: one number, or Z,Y,X.
        #[arg(long, default_value = "64", value_parser = parse_edge)]
        chunk: [u64; 3],
        /// Zarr v3 shard edge in voxels (one number or Z,Y,X; a multiple of --chunk).
        #[arg(long, value_parser = parse_edge)]
        shard: Option<[u64; 3]>,
        /// OME-Zarr version: 0.5 (Zarr v3) or 0.4 (Zarr v2).
        #[arg(long, value_enum, default_value = "0.5")]
        ome_zarr_version: Version,
        /// Number of pyramid levels (default: until a level fits in one brick).
        #[arg(long)]
        levels: Option<usize>,
        /// Channel labels, comma-separated, overriding the input metadata.
        #[arg(long, value_delimiter = ',')]
        channel_names: Vec<String>,
        /// Replace an existing output.
        #[arg(long)]
        overwrite: bool,
        /// Convert only partition I of N (counted from 0): its range of planes, whole slabs of
        /// every level it covers; run all N (in any order, anywhere), then `ingest finalize`.
        #[arg(long, value_name = "I/N")]
        partition: Option<Partition>,
        /// Peak memory to stay within: bytes, or with K, M, G or T (powers of 1024), e.g. 4G
        /// (default: half of this machine's memory). Planes too large for it are converted in
        /// columns of whole chunks, reading only the strips, tiles or rows each column spans.
        #[arg(long, value_name = "BYTES", value_parser = parse_bytes)]
        memory_limit: Option<u64>,
        /// Copy every input plane into memory. By default whole planes stored uncompressed
        /// (in the output's sample type and this machine's byte order) are mapped from their
        /// files and read where they lie; use this for inputs that may change while the
        /// conversion runs, since a mapped file cut short meanwhile ends it with SIGBUS.
        #[arg(long)]
        no_mmap: bool,
        /// Worker threads (default: all cores).
        #[arg(long)]
        threads: Option<usize>,
        /// Hide the progress bar.
        #[arg(long)]
        quiet: bool,
    },
    /// Finish a store converted in partitions (`convert --partition I/N`): merge their region
    /// metadata, write the coarse levels, and write the root metadata last.
    Finalize {
        /// The store the partitions wrote (the same -o).
        #[arg(short, long)]
        output: StoreLocation,
        /// Endpoint URL of an S3-compatible server that is not AWS, for an s3:// output
        /// (default: AWS_ENDPOINT_URL, else AWS).
        #[arg(long, value_name = "URL")]
        s3_endpoint: Option<String>,
        /// Replace an existing output (a folder only).
        #[arg(long)]
        overwrite: bool,
        /// Worker threads (default: all cores).
        #[arg(long)]
        threads: Option<usize>,
        /// Hide the progress bar.
        #[arg(long)]
        quiet: bool,
    },
    /// Write a built-in synthetic sample (one OME-TIFF per channel).
    Sample {
        /// Output folder.
        #[arg(short, long)]
        output: PathBuf,
        /// Which specimen.
        #[arg(long, default_value = "fluorescence", value_parser = sample_kinds())]
        kind: SampleKind,
        /// Extent Z,Y,X in voxels (default: 96,256,256 for fluorescence, 256,256,256 for
        /// sparse, dense and mixing, 24,256,256 for cycif).
        #[arg(long, value_parser = parse_triple_u64)]
        size: Option<[u64; 3]>,
        /// Number of channels (default: 3 for fluorescence, which has exactly 3; 1 for sparse
        /// dense and mixing, whose extra channels are other transfer functions; 16 for cycif).
        #[arg(long)]
        channels: Option<usize>,
        /// Random seed.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Worker threads (default: all cores).
        #[arg(long)]
        threads: Option<usize>,
        /// Hide the progress bar.
        #[arg(long)]
        quiet: bool,
    },
    /// Add region metadata to an OME-Zarr image written by another tool, without rewriting its data.
    Index {
        /// The OME-Zarr image group: a folder, a file:// URL, or s3://BUCKET/PREFIX.
        store: StoreLocation,
        /// Endpoint URL of an S3-compatible server that is not AWS (default: AWS_ENDPOINT_URL,
        /// else AWS).
        #[arg(long, value_name = "URL")]
        s3_endpoint: Option<String>,
        /// Worker threads (default: all cores).
        #[arg(long)]
        threads: Option<usize>,
    },
    /// Print levels, shapes, chunking, codecs, voxel sizes, channel statistics and metadata coverage.
    Inspect {
        /// The OME-Zarr image group: a folder, a file:// URL, or s3://BUCKET/PREFIX (credentials
        /// and region from the AWS variables).
        store: StoreLocation,
        /// Endpoint URL of an S3-compatible server that is not AWS (default: AWS_ENDPOINT_URL,
        /// else AWS).
        #[arg(long, value_name = "URL")]
        s3_endpoint: Option<String>,
    },
}

fn parse_list<T: std::str::FromStr>(s: &str) -> Result<Vec<T>, String> {
    s.split(',')
        .map(|p| {
            p.trim()
                .parse::<T>()
                .map_err(|_| format!("'{p}' is not a valid number"))
        })
        .collect()
}

/// A byte count: digits, then optionally K, M, G or T (powers of 1024), with or without a
/// trailing `B` or `iB`.
fn parse_bytes(s: &str) -> Result<u64, String> {
    let t = s.trim();
    let t = t
        .strip_suffix("iB")
        .or_else(|| t.strip_suffix('B'))
        .unwrap_or(t);
    let (digits, shift) = match t.char_indices().last() {
        Some((i, 'K' | 'k')) => (&t[..i], 10),
        Some((i, 'M' | 'm')) => (&t[..i], 20),
        Some((i, 'G' | 'g')) => (&t[..i], 30),
        Some((i, 'T' | 't')) => (&t[..i], 40),
        _ => (t, 0),
    };
    digits
        .parse::<u64>()
        .ok()
        .and_then(|n| n.checked_mul(1 << shift))
        .filter(|&n| n > 0)
        .ok_or_else(|| format!("expected a positive byte count such as 4G or 500M, not {s:?}"))
}

fn parse_triple_u64(s: &str) -> Result<[u64; 3], String> {
    parse_list::<u64>(s)?
        .try_into()
        .map_err(|_| format!("expected three comma-separated numbers, got '{s}'"))
}

fn parse_triple_f64(s: &str) -> Result<[f64; 3], String> {
    parse_list::<f64>(s)?
        .try_into()
        .map_err(|_| format!("expected three comma-separated numbers, got '{s}'"))
}

fn parse_edge(s: &str) -> Result<[u64; 3], String> {
    match parse_list::<u64>(s)?[..] {
        [e] => Ok([e; 3]),
        [z, y, x] => Ok([z, y, x]),
        _ => Err(format!("expected one number or Z,Y,X, got '{s}'")),
    }
}

/// Partitions write into an object store's prefix directly, so an old store there would mix
/// with the new one: they refuse to replace it.
fn refuse_s3_overwrite(output: &StoreLocation, overwrite: bool) -> Result<()> {
    if overwrite && output.folder().is_none() {
        bail!(
            "{output}: --overwrite does not combine with partitions in an object store (their keys would mix with the old store's); delete the old store first"
        );
    }
    Ok(())
}

/// Uploads `folder` (of `bytes` bytes) to the object-store location `output` with a progress
/// bar (see [`StoreLocation::upload_folder`] for `clear` and `scratch`).
fn upload(
    output: &StoreLocation,
    folder: &std::path::Path,
    s3: &ObjectStoreOptions,
    clear: bool,
    scratch: Option<&str>,
    bytes: u64,
    quiet: bool,
) -> Result<()> {
    let bar = bytes_bar(bytes, "uploading", !quiet);
    output.upload_folder(folder, s3, clear, scratch, &|n| bar.inc(n))?;
    bar.finish_and_clear();
    Ok(())
}

fn set_threads(threads: Option<usize>) -> Result<()> {
    if let Some(n) = threads {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build_global()
            .context("cannot set up the thread pool")?;
    }
    Ok(())
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Convert {
            inputs,
            output,
            s3_endpoint,
            dims,
            dtype,
            endian,
            header_bytes,
            voxel_size,
            unit,
            chunk,
            shard,
            ome_zarr_version,
            levels,
            channel_names,
            overwrite,
            partition,
            memory_limit,
            no_mmap,
            threads,
            quiet,
        } => {
            set_threads(threads)?;
            if levels == Some(0) {
                bail!("--levels must be at least 1");
            }
            let s3 = ObjectStoreOptions::for_location(&output, s3_endpoint)?;
            if partition.is_some() {
                refuse_s3_overwrite(&output, overwrite)?;
            }
            // An object-store output is converted in a local folder first, then published.
            let (local, staging) = match &output {
                StoreLocation::Folder(path) => (path.clone(), None),
                StoreLocation::S3 { .. } => {
                    output.check_absent(&s3, overwrite)?;
                    let dir = tempfile::Builder::new()
                        .prefix("ingest-staging-")
                        .tempdir()
                        .context("cannot create a local staging folder")?;
                    (dir.path().join(output.file_name()), Some(dir))
                }
            };
            let mut options = ConvertOptions::new(inputs, local.clone());
            options.raw = RawOptions {
                dims,
                format: dtype.as_deref().map(str::parse::<SampleType>).transpose()?,
                big_endian: matches!(endian, Endian::Big),
                header_bytes,
            };
            options.voxel_size = voxel_size;
            options.unit = unit;
            options.brick = chunk;
            options.shard = shard;
            options.version = match ome_zarr_version {
                Version::V05 => OmeZarrVersion::V05,
                Version::V04 => OmeZarrVersion::V04,
            };
            options.levels = levels;
            options.overwrite = overwrite;
            options.progress = !quiet;
            options.channel_names = channel_names;
            options.memory_limit = memory_limit;
            options.map_inputs = !no_mmap;
            if let Some(partition) = partition {
                let mut summary = convert_partition(&options, partition)?;
                if staging.is_some() {
                    // Straight into the bucket: no root metadata, so no reader takes it for a
                    // store before `finalize`.
                    let bytes = directory_bytes(&summary.folder);
                    upload(&output, &summary.folder, &s3, false, None, bytes, quiet)?;
                    summary.folder = PathBuf::from(output.to_string());
                }
                out(format_args!("{}", summary.report()))?;
                return Ok(());
            }
            let mut summary = convert(&options)?;
            if staging.is_some() {
                // Replacing a store clears its old keys, root metadata first.
                upload(
                    &output,
                    &local,
                    &s3,
                    overwrite,
                    None,
                    summary.stored_bytes,
                    quiet,
                )?;
                summary.output = PathBuf::from(output.to_string());
            }
            out(format_args!("{}", summary.report()))?;
        }
        Command::Finalize {
            output,
            s3_endpoint,
            overwrite,
            threads,
            quiet,
        } => {
            set_threads(threads)?;
            let s3 = ObjectStoreOptions::for_location(&output, s3_endpoint)?;
            let summary = match &output {
                StoreLocation::Folder(path) => {
                    finalize(path, &path.display().to_string(), overwrite, !quiet)?
                }
                StoreLocation::S3 { .. } => {
                    refuse_s3_overwrite(&output, overwrite)?;
                    output.check_absent(&s3, false)?;
                    let dir = tempfile::Builder::new()
                        .prefix("ingest-finalize-")
                        .tempdir()
                        .context("cannot create a local staging folder")?;
                    let local = dir.path().join(output.file_name());
                    output.download_prefix(HANDOFF_FOLDER, &partial_path(&local), &s3)?;
                    let mut summary = finalize(&local, &output.to_string(), false, !quiet)?;
                    // The partitions' bricks are in the bucket already: this adds the rest,
                    // removes the hand-over files, and writes the root metadata last.
                    let bytes = directory_bytes(&local);
                    upload(
                        &output,
                        &local,
                        &s3,
                        false,
                        Some(HANDOFF_FOLDER),
                        bytes,
                        quiet,
                    )?;
                    summary.output = PathBuf::from(output.to_string());
                    summary
                }
            };
            out(format_args!("{}", summary.report()))?;
        }
        Command::Sample {
            output,
            kind,
            size,
            channels,
            seed,
            threads,
            quiet,
        } => {
            set_threads(threads)?;
            let defaults = SampleSpec::new(kind);
            let spec = SampleSpec {
                kind,
                shape: size.unwrap_or(defaults.shape),
                channels: channels.unwrap_or(defaults.channels),
                seed,
            };
            let files = write_samples(&output, &spec, !quiet)?;
            let [z, y, x] = spec.shape;
            out(format_args!(
                "wrote the {kind} sample stack ({z} x {y} x {x} voxels, z,y,x; {} channels):\n",
                spec.channels
            ))?;
            for f in &files {
                out(format_args!("  {}\n", f.display()))?;
            }
            let list: Vec<String> = files.iter().map(|f| f.display().to_string()).collect();
            out(format_args!(
                "convert it with: ingest convert {} -o sample.ome.zarr\n",
                list.join(" ")
            ))?;
        }
        Command::Index {
            store,
            s3_endpoint,
            threads,
        } => {
            set_threads(threads)?;
            let options = ObjectStoreOptions::for_location(&store, s3_endpoint)?;
            let report = residency_ingest::index::index(&store, &options)?;
            out(format_args!("{report}"))?;
        }
        Command::Inspect { store, s3_endpoint } => {
            let options = ObjectStoreOptions::for_location(&store, s3_endpoint)?;
            out(format_args!(
                "{}",
                residency_ingest::inspect::inspect(&store, &options)?
            ))?;
        }
    }
    Ok(())
}

/// The reader of stdout has gone (a closed pipe): the program ends with success, its work done
/// (see [`out`]).
#[derive(Debug, thiserror::Error)]
#[error("the reader of the report has gone")]
struct ReaderGone;

/// Writes `text` to stdout. When the reader has gone (`ingest inspect STORE | head`), the
/// program ends quietly with success, as ripgrep does, instead of panicking on a broken pipe:
/// everything it had to do is done by the time it reports, and returning (not exiting here)
/// lets it clean up on the way out (an S3 upload's staging folder).
///
/// # Errors
/// [`ReaderGone`] on a broken pipe, or why stdout cannot be written.
fn out(text: std::fmt::Arguments) -> Result<()> {
    use std::io::Write;
    let mut stdout = std::io::stdout().lock();
    match stdout.write_fmt(text).and_then(|()| stdout.flush()) {
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Err(ReaderGone.into()),
        other => Ok(other?),
    }
}

fn main() -> ExitCode {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "warn".into()),
        )
        .with_writer(std::io::stderr)
        .init();
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) if e.is::<ReaderGone>() => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!(
                "error: {}",
                residency_schemas::error_chain::join_chain(e.chain())
            );
            ExitCode::FAILURE
        }
    }
}

#[cfg(test)]
mod tests {
    use clap::CommandFactory;

    use super::*;

    /// The `--kind` of `ingest sample ARGS`, or clap's error.
    fn kind(args: &[&str]) -> Result<SampleKind, clap::Error> {
        let argv = ["ingest", "sample", "-o", "out"].iter().chain(args);
        match Cli::try_parse_from(argv)?.command {
            Command::Sample { kind, .. } => Ok(kind),
            _ => unreachable!("the sample command"),
        }
    }

    #[test]
    fn sample_kinds_are_parsed_by_their_names() {
        Cli::command().debug_assert();
        assert_eq!(kind(&[]).unwrap(), SampleKind::Fluorescence);
        for &k in SampleKind::VARIANTS {
            assert_eq!(kind(&["--kind", k.into()]).unwrap(), k);
        }
        for bad in ["Sparse", "ct"] {
            let e = kind(&["--kind", bad]).unwrap_err();
            assert_eq!(e.kind(), clap::error::ErrorKind::InvalidValue);
        }
    }
}
