//! Array metadata for Zarr v2 (OME-Zarr 0.4) and v3 (OME-Zarr 0.5): the layout of an array
//! ([`ArrayLayout`]), the blosc-lz4 codec at level [`BLOSC_CLEVEL`], optional sharding, and
//! the group document of Zarr v3.

use std::sync::Arc;

use residency_schemas::SampleType;
use residency_schemas::ome::OmeZarrVersion;
use serde::Serialize;
use serde_json::Value;
use zarrs::array::codec::array_to_bytes::sharding::ShardingCodecBuilder;
use zarrs::array::codec::{BloscCodec, BytesCodec, Crc32cCodec};
use zarrs::array::{ArrayBuilder, ArrayMetadata};
use zarrs::metadata::ChunkKeySeparator;
use zarrs::metadata::v2::{ArrayMetadataV2, MetadataV2};
use zarrs::metadata::v3::FillValueMetadataV3;
use zarrs::metadata_ext::codec::blosc::{
    BloscCodecConfigurationNumcodecs, BloscCompressionLevel, BloscCompressor, BloscShuffleMode,
    BloscShuffleModeNumcodecs,
};

use super::error::StoreError;

/// Blosc compression level used for every array.
pub(crate) const BLOSC_CLEVEL: u8 = 5;

/// Layout of one array: shape, chunking, data type.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct ArrayLayout {
    /// Array shape.
    pub shape: Vec<u64>,
    /// Zarr chunk shape (the shard shape when sharded).
    pub chunk: Vec<u64>,
    /// Inner chunk (brick) shape when sharded.
    pub inner_chunk: Option<Vec<u64>>,
    /// Data type.
    pub format: SampleType,
    /// Dimension names (Zarr v3 only).
    pub dimension_names: Option<Vec<&'static str>>,
}

/// [`BLOSC_CLEVEL`] as zarrs' level.
fn blosc_level() -> Result<BloscCompressionLevel, StoreError> {
    BloscCompressionLevel::try_from(BLOSC_CLEVEL).map_err(|rejected| StoreError::BloscLevel {
        level: BLOSC_CLEVEL,
        rejected,
    })
}

/// The Blosc codec every array uses: LZ4 with byte shuffle, level [`BLOSC_CLEVEL`], automatic
/// block size.
fn blosc(format: SampleType) -> Result<BloscCodec, StoreError> {
    BloscCodec::new(
        BloscCompressor::LZ4,
        blosc_level()?,
        None,
        BloscShuffleMode::Shuffle,
        Some(format.bytes()),
    )
    .map_err(StoreError::BloscCodec)
}

/// A Zarr v3 group document. zarrs' `GroupMetadataV3` leaves out empty attributes; the stores
/// we have always written keep `"attributes": {}`, and must stay byte-identical.
#[derive(Serialize)]
pub(crate) struct GroupDocumentV3<'a> {
    pub(crate) zarr_format: u8,
    pub(crate) node_type: &'static str,
    pub(crate) attributes: &'a serde_json::Map<String, Value>,
}

/// The Zarr v2 `compressor` of an array: numcodecs' Blosc with the same settings as [`blosc`].
#[derive(Serialize)]
struct NumcodecsBlosc {
    id: &'static str,
    #[serde(flatten)]
    configuration: BloscCodecConfigurationNumcodecs,
}

/// Builds the Zarr metadata of an array, through zarrs' typed builders: v3 with the `bytes`
/// and `blosc` codecs (inside `sharding_indexed`, with a little-endian, CRC32C-checked index at
/// the end, when sharded), or v2 with the Blosc compressor.
///
/// # Errors
/// When sharding is asked of Zarr v2, a chunk edge is 0, or zarrs refuses the layout.
pub(crate) fn array_metadata(
    version: OmeZarrVersion,
    layout: &ArrayLayout,
) -> Result<ArrayMetadata, StoreError> {
    let nonzero = |v: &[u64]| -> Result<Vec<std::num::NonZeroU64>, StoreError> {
        v.iter()
            .map(|&e| std::num::NonZeroU64::new(e).ok_or(StoreError::ZeroChunkEdge))
            .collect()
    };
    Ok(match version {
        OmeZarrVersion::V04 => {
            if layout.inner_chunk.is_some() {
                return Err(StoreError::ShardingNeedsV3);
            }
            let compressor: MetadataV2 =
                serde_json::from_value(serde_json::to_value(NumcodecsBlosc {
                    id: "blosc",
                    configuration: BloscCodecConfigurationNumcodecs {
                        cname: BloscCompressor::LZ4,
                        clevel: blosc_level()?,
                        shuffle: BloscShuffleModeNumcodecs::Shuffle,
                        blocksize: 0,
                    },
                })?)?;
            ArrayMetadata::V2(
                ArrayMetadataV2::new(
                    layout.shape.clone(),
                    nonzero(&layout.chunk)?,
                    layout.format.zarr_v2_dtype().into(),
                    FillValueMetadataV3::from(0),
                    Some(compressor),
                    None,
                )
                .with_dimension_separator(ChunkKeySeparator::Slash),
            )
        }
        OmeZarrVersion::V05 => {
            let data_type = zarrs::array::DataType::from_metadata(
                &zarrs::metadata::v3::MetadataV3::new(layout.format.zarr_name()),
            )
            .map_err(StoreError::DataType)?;
            let mut builder = ArrayBuilder::new(
                layout.shape.clone(),
                layout.chunk.as_slice(),
                data_type.clone(),
                FillValueMetadataV3::from(0),
            );
            builder.chunk_key_encoding_default_separator(ChunkKeySeparator::Slash);
            match &layout.inner_chunk {
                None => {
                    builder
                        .array_to_bytes_codec(Arc::new(BytesCodec::little()))
                        .bytes_to_bytes_codecs(vec![Arc::new(blosc(layout.format)?)]);
                }
                Some(inner) => {
                    let mut sharding = ShardingCodecBuilder::new(nonzero(inner)?, &data_type);
                    sharding
                        .array_to_bytes_codec(Arc::new(BytesCodec::little()))
                        .bytes_to_bytes_codecs(vec![Arc::new(blosc(layout.format)?)])
                        .index_array_to_bytes_codec(Arc::new(BytesCodec::little()))
                        .index_bytes_to_bytes_codecs(vec![Arc::new(Crc32cCodec::new())]);
                    builder.array_to_bytes_codec(sharding.build_arc());
                }
            }
            builder.dimension_names(layout.dimension_names.clone());
            let mut metadata = builder
                .build_metadata()
                .map_err(|e| StoreError::ArrayMetadata(Box::new(e)))?;
            // zarrs writes a float fill value as `0.0`; our stores have always said `0` (the
            // same number to every reader), and must stay byte-identical.
            metadata.fill_value = FillValueMetadataV3::from(0);
            ArrayMetadata::V3(metadata)
        }
    })
}
