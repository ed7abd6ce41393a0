//! What `ingest convert` is asked to do ([`ConvertOptions`]).

use std::path::PathBuf;

use crate::progress::ProgressCallback;
use crate::source::RawOptions;
use crate::store::OmeZarrVersion;

/// Everything `ingest convert` needs to know.
#[derive(Clone, Debug)]
pub struct ConvertOptions {
    /// Input files, folders or globs; their channels are concatenated in order.
    pub inputs: Vec<String>,
    /// Output store path.
    pub output: PathBuf,
    /// Layout of raw inputs.
    pub raw: RawOptions,
    /// Voxel size `z, y, x` overriding the inputs' metadata.
    pub voxel_size: Option<[f64; 3]>,
    /// Physical unit overriding the inputs' metadata.
    pub unit: Option<String>,
    /// Brick (chunk, or inner chunk when sharded) shape `z, y, x`.
    pub brick: [u64; 3],
    /// Shard shape `z, y, x` (Zarr v3 sharding), a multiple of the brick.
    pub shard: Option<[u64; 3]>,
    /// OME-Zarr version.
    pub version: OmeZarrVersion,
    /// Number of levels (default: until a level fits in one brick).
    pub levels: Option<usize>,
    /// Replace an existing output.
    pub overwrite: bool,
    /// Show a progress bar on stderr.
    pub progress: bool,
    /// Channel labels overriding the inputs' metadata.
    pub channel_names: Vec<String>,
    /// Peak memory to stay within, in bytes (default: [`default_memory_limit`]).
    pub memory_limit: Option<u64>,
    /// Map whole input planes that their files store as they are read (uncompressed, in the
    /// output's sample type and the machine's byte order) instead of copying them into
    /// memory: the page cache's own memory is read in place. Only for inputs that do not
    /// change during the conversion (a mapped file truncated meanwhile ends the process).
    pub map_inputs: bool,
    /// Told the input bytes read so far and the pass's total as the conversion goes on (a
    /// conversion within a memory limit may read in several passes), beside the bar.
    pub on_progress: Option<ProgressCallback>,
}

/// The memory a conversion keeps within unless told otherwise: half of this machine's
/// physical memory (no limit where the system does not say).
pub fn default_memory_limit() -> u64 {
    crate::memory::physical_memory().map_or(u64::MAX, |m| m / 2)
}

impl ConvertOptions {
    /// The memory this conversion keeps within: [`Self::memory_limit`], else
    /// [`default_memory_limit`].
    pub fn memory_limit_or_default(&self) -> u64 {
        self.memory_limit.unwrap_or_else(default_memory_limit)
    }

    /// Options with defaults for everything but inputs and output.
    pub fn new(inputs: Vec<String>, output: PathBuf) -> Self {
        Self {
            inputs,
            output,
            raw: RawOptions::default(),
            voxel_size: None,
            unit: None,
            brick: [64; 3],
            shard: None,
            version: OmeZarrVersion::V05,
            levels: None,
            overwrite: false,
            progress: false,
            channel_names: Vec::new(),
            memory_limit: None,
            map_inputs: true,
            on_progress: None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The README's default: half the machine's memory, what a conversion plans its
    /// columns within (`plan_pass`) unless `--memory-limit` says otherwise.
    #[test]
    fn the_default_memory_limit_is_half_the_physical_memory() {
        let physical = crate::memory::physical_memory().expect("sysconf gives the memory");
        let mut options = ConvertOptions::new(vec!["a.tif".into()], "a.ome.zarr".into());
        assert_eq!(options.memory_limit_or_default(), physical / 2);
        options.memory_limit = Some(1 << 30);
        assert_eq!(options.memory_limit_or_default(), 1 << 30);
    }
}
