//! Reading a region-metadata array (a min/max grid, a histogram, a region index) through zarrs:
//! the whole array, or one channel's slice of it (the first axis is the channel), as its
//! little-endian bytes and as `f64` values. `brickserver`'s region queries and the Python
//! module's region arrays both read through it.

use std::sync::Arc;

use zarrs::array::{Array, ArrayBytes, ArrayCreateError, ArrayError, ArraySubset};
use zarrs::storage::ReadableStorageTraits;

use residency_schemas::SampleType;
use residency_schemas::sample_type::PartialSample;

/// The part of a region array to read.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ArrayPart {
    /// Every value.
    Whole,
    /// The values of one channel: index `c` of the first axis, all of the others.
    Channel(u64),
}

/// Why a region array cannot be read.
#[derive(Debug, thiserror::Error)]
pub enum RegionArrayError {
    /// zarrs cannot open the array (missing or unusable metadata).
    #[error(transparent)]
    Open(#[from] ArrayCreateError),
    /// The array's chunks cannot be read or decoded.
    #[error(transparent)]
    Retrieve(#[from] ArrayError),
    /// The channel asked for is past the array's first axis (zarrs would answer fill values).
    #[error("channel {channel} is past the array's {channels} channels")]
    NoChannel {
        /// The channel asked for.
        channel: u64,
        /// Channels of the array (its first axis).
        channels: u64,
    },
    /// The bytes are not a whole number of values of the sample type.
    #[error(transparent)]
    Decode(#[from] PartialSample),
}

/// The values of `part` of the array at `path` (a key prefix without the leading `/`) of
/// `store`, stored as `sample_type`: their little-endian bytes, and the values as `f64`.
///
/// # Errors
/// [`RegionArrayError`]: the array cannot be opened, read or decoded.
pub fn read_region_array<S: ReadableStorageTraits + ?Sized + 'static>(
    store: &Arc<S>,
    path: &str,
    part: ArrayPart,
    sample_type: SampleType,
) -> Result<(Vec<u8>, Vec<f64>), RegionArrayError> {
    let array = Array::open(store.clone(), &format!("/{path}"))?;
    let shape = array.shape().to_vec();
    let subset = match part {
        ArrayPart::Whole => ArraySubset::new_with_shape(shape),
        ArrayPart::Channel(c) => {
            let channels = shape.first().copied().unwrap_or(0);
            if c >= channels {
                return Err(RegionArrayError::NoChannel {
                    channel: c,
                    channels,
                });
            }
            let ranges: Vec<std::ops::Range<u64>> = std::iter::once(c..c + 1)
                .chain(shape.iter().skip(1).map(|&s| 0..s))
                .collect();
            ArraySubset::new_with_ranges(&ranges)
        }
    };
    let bytes: ArrayBytes<'static> = array.retrieve_array_subset(&subset)?;
    // Region arrays are of fixed-size numbers; zarrs reports anything else as an array error.
    let raw = bytes.into_fixed().map_err(ArrayError::from)?.into_owned();
    let values = sample_type.decode_le_to_f64(&raw)?;
    Ok((raw, values))
}

#[cfg(test)]
mod tests {
    use super::*;
    use zarrs::array::{ArrayBuilder, DataType};
    use zarrs::filesystem::FilesystemStore;
    use zarrs::metadata::v3::{FillValueMetadataV3, MetadataV3};

    /// Writes a uint16 array of `shape` at `/NAME` (chunks `[1, 2, 2]`), values 0, 1, 2, ...
    fn write_u16(store: &Arc<FilesystemStore>, name: &str, shape: Vec<u64>) {
        let data_type = DataType::from_metadata(&MetadataV3::new("uint16")).unwrap();
        let array = ArrayBuilder::new(
            shape.clone(),
            [1, 2, 2],
            data_type,
            FillValueMetadataV3::from(0),
        )
        .build(store.clone(), &format!("/{name}"))
        .unwrap();
        array.store_metadata().unwrap();
        let n = u16::try_from(shape.iter().product::<u64>()).unwrap();
        let values: Vec<u16> = (0..n).collect();
        array
            .store_array_subset(&ArraySubset::new_with_shape(shape), values.as_slice())
            .unwrap();
    }

    /// `/grid`, `[2, 2, 3]` (a channel's slice spans two chunks), and `/odd`, `[1, 1, 3]` (6
    /// bytes).
    fn store_with_grid(dir: &std::path::Path) -> Arc<FilesystemStore> {
        let store = Arc::new(FilesystemStore::new(dir).unwrap());
        write_u16(&store, "grid", vec![2, 2, 3]);
        write_u16(&store, "odd", vec![1, 1, 3]);
        store
    }

    #[test]
    fn a_whole_array_and_a_channel_read_as_bytes_and_values() {
        let dir = tempfile::tempdir().unwrap();
        let store = store_with_grid(dir.path());
        let (raw, values) =
            read_region_array(&store, "grid", ArrayPart::Whole, SampleType::U16).unwrap();
        assert_eq!(values, (0..12).map(f64::from).collect::<Vec<_>>());
        assert_eq!(
            raw,
            (0..12u16).flat_map(u16::to_le_bytes).collect::<Vec<_>>()
        );
        let (raw, values) =
            read_region_array(&store, "grid", ArrayPart::Channel(1), SampleType::U16).unwrap();
        assert_eq!(values, [6.0, 7.0, 8.0, 9.0, 10.0, 11.0]);
        assert_eq!(
            raw,
            (6..12u16).flat_map(u16::to_le_bytes).collect::<Vec<_>>()
        );
    }

    #[test]
    fn a_missing_array_a_channel_past_the_end_and_a_wrong_sample_type_are_errors() {
        let dir = tempfile::tempdir().unwrap();
        let store = store_with_grid(dir.path());
        let missing = read_region_array(&store, "none", ArrayPart::Whole, SampleType::U16);
        assert!(
            matches!(missing, Err(RegionArrayError::Open(_))),
            "{missing:?}"
        );
        let past = read_region_array(&store, "grid", ArrayPart::Channel(2), SampleType::U16);
        assert_eq!(
            past.unwrap_err().to_string(),
            "channel 2 is past the array's 2 channels"
        );
        // 6 bytes are not a whole number of 4-byte values.
        let partial = read_region_array(&store, "odd", ArrayPart::Whole, SampleType::U32);
        assert!(
            matches!(partial, Err(RegionArrayError::Decode(_))),
            "{partial:?}"
        );
    }
}
