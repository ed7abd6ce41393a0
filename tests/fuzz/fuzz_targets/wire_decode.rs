//! The framed wire documents (`schemas/src/wire.rs`): `decode_framed` of `RSMINMAX` min/max
//! hierarchies and `RSBRICKS` brick batches on any bytes, then, as a client does, every grid
//! or brick cut out of the payload at the offsets the header claims and decoded with the
//! header's sample type (`SampleType::decode_le_to_f64`, formerly `wire::samples_to_f64`). A
//! decoded header must frame and decode back to itself.
#![no_main]

use libfuzzer_sys::fuzz_target;
use residency_schemas::wire::{
    BRICKS_MAGIC, BrickBatchHeader, BrickStatus, MINMAX_MAGIC, MinMaxHierarchyHeader,
    decode_framed, encode_framed,
};

fn cut(payload: &[u8], offset: u64, length: u64) -> Option<&[u8]> {
    let o = usize::try_from(offset).ok()?;
    let l = usize::try_from(length).ok()?;
    payload.get(o..o.checked_add(l)?)
}

fuzz_target!(|data: &[u8]| {
    if let Ok((header, payload)) = decode_framed::<MinMaxHierarchyHeader>(MINMAX_MAGIC, data) {
        for level in &header.levels {
            for grid in &level.grids {
                if let Some(bytes) = cut(payload, grid.offset, grid.length)
                    && let Ok(values) = header.data_type.decode_le_to_f64(bytes)
                {
                    assert_eq!(values.len() * header.data_type.bytes(), bytes.len());
                }
            }
        }
        let again = encode_framed(MINMAX_MAGIC, &header, payload);
        let (back, rest) = decode_framed::<MinMaxHierarchyHeader>(MINMAX_MAGIC, &again).unwrap();
        assert_eq!((back, rest), (header, payload));
    }
    if let Ok((header, payload)) = decode_framed::<BrickBatchHeader>(BRICKS_MAGIC, data) {
        for brick in &header.bricks {
            if brick.status == BrickStatus::Ok
                && let Some(bytes) = cut(payload, brick.offset, brick.length)
                && let Ok(values) = header.data_type.decode_le_to_f64(bytes)
            {
                assert_eq!(values.len() * header.data_type.bytes(), bytes.len());
            }
        }
        let again = encode_framed(BRICKS_MAGIC, &header, payload);
        let (back, rest) = decode_framed::<BrickBatchHeader>(BRICKS_MAGIC, &again).unwrap();
        assert_eq!((back, rest), (header, payload));
    }
});
