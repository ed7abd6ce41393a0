//! Planes lent by their file ([`MappedPlane`]): a plane stored uncompressed, in the sample
//! type and byte order the converter works in, is the page cache's own memory mapped
//! read-only, so the converter reads it where it lies instead of copying it into a slab.

use std::fs::File;
use std::path::Path;

use memmap2::{Mmap, MmapOptions};

use crate::sample_format::Sample;

/// One whole plane of an input, mapped from its file.
///
/// Mapping assumes the file does not change while the plane is mapped: a file truncated under
/// a conversion, or a disk that fails to read a mapped page, ends it with `SIGBUS` instead of
/// an error, so a conversion of inputs that may change reads them instead
/// (`ConvertOptions::map_inputs`).
pub struct MappedPlane {
    bytes: PlaneBytes,
}

/// Where a [`MappedPlane`]'s bytes are.
enum PlaneBytes {
    /// In the mapping, from `start` (the mapping starts on a page boundary).
    InPlace { map: Mmap, start: usize, len: usize },
    /// Copied out of the mapping into words, because in the file they do not start on a
    /// multiple of their samples' size (a TIFF page after an odd-length description).
    Copied { words: Vec<u64>, len: usize },
}

impl MappedPlane {
    /// Maps `len` bytes at `offset` of `file` (`path`, `file_len` bytes long), with its page
    /// table filled now ([`MmapOptions::populate`]): the mapping thread, not the converter's
    /// workers, waits for the disk and takes the page faults. Bytes that do not start on a
    /// multiple of `align`, the samples' size, are copied once out of the mapping (a slice of
    /// samples must be aligned). None when the bytes do not lie inside the file, or the system
    /// refuses the mapping (a file system that cannot map, or too many mappings): the plane is
    /// then read instead.
    pub(crate) fn map(
        file: &File,
        path: &Path,
        (offset, len): (u64, u64),
        file_len: u64,
        align: usize,
    ) -> Option<Self> {
        let page = crate::memory::page_size().unwrap_or(4096);
        let inside = offset.checked_add(len).is_some_and(|end| end <= file_len);
        if !inside || len == 0 {
            return None;
        }
        let base = offset / page * page;
        let start = (offset - base) as usize;
        let (Ok(len), Ok(mapped)) = (usize::try_from(len), usize::try_from(len + offset - base))
        else {
            return None;
        };
        // SAFETY: the mapping is read-only and lies inside the file (checked above). Its
        // contents change only if another process writes the file during the conversion,
        // which `MappedPlane`'s documentation rules out.
        let map = match unsafe {
            MmapOptions::new()
                .offset(base)
                .len(mapped)
                .populate()
                .map(file)
        } {
            Ok(map) => map,
            Err(error) => {
                tracing::debug!("{}: not mapped at byte {offset}: {error}", path.display());
                return None;
            }
        };
        let bytes = if offset.is_multiple_of(align as u64) {
            PlaneBytes::InPlace { map, start, len }
        } else {
            let mut words = vec![0u64; len.div_ceil(8)];
            bytemuck::cast_slice_mut::<u64, u8>(&mut words)[..len]
                .copy_from_slice(&map[start..start + len]);
            PlaneBytes::Copied { words, len }
        };
        Some(Self { bytes })
    }

    /// Whether the plane is read where it lies in the page cache (not copied).
    pub fn in_place(&self) -> bool {
        matches!(self.bytes, PlaneBytes::InPlace { .. })
    }

    /// Bytes of the plane.
    pub fn byte_len(&self) -> usize {
        match &self.bytes {
            PlaneBytes::InPlace { len, .. } | PlaneBytes::Copied { len, .. } => *len,
        }
    }

    /// The plane's samples.
    ///
    /// # Panics
    /// When `T` is not the sample type the plane was mapped for (its alignment or size do not
    /// fit): a converter bug.
    pub fn samples<T: Sample>(&self) -> &[T] {
        let bytes = match &self.bytes {
            PlaneBytes::InPlace { map, start, len } => &map[*start..*start + *len],
            PlaneBytes::Copied { words, len } => &bytemuck::cast_slice::<u64, u8>(words)[..*len],
        };
        bytemuck::cast_slice(bytes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_plane_is_lent_where_it_lies_copied_when_misaligned_and_refused_outside_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("planes.raw");
        // 8198 bytes of header (more than a page), then 3 planes of 2 × 3 u16.
        let mut bytes = vec![0xAAu8; 8198];
        bytes.extend((0u16..18).flat_map(|v| (v * 1000).to_le_bytes()));
        std::fs::write(&path, &bytes).unwrap();
        let file = File::open(&path).unwrap();
        let len = bytes.len() as u64;
        // The second plane: 12 bytes at 8198 + 12, across no page boundary.
        let plane = MappedPlane::map(&file, &path, (8210, 12), len, 2).unwrap();
        assert_eq!(
            plane.samples::<u16>(),
            &[6000, 7000, 8000, 9000, 10000, 11000]
        );
        assert!(plane.in_place());
        // A plane past the end of the file is read instead.
        assert!(MappedPlane::map(&file, &path, (8222, 14), len, 2).is_none());
        // Samples at an odd offset are copied once into aligned memory.
        let odd = MappedPlane::map(&file, &path, (8209, 12), len, 2).unwrap();
        assert!(!odd.in_place());
        let expected: Vec<u16> = bytes[8209..8221]
            .chunks(2)
            .map(|b| u16::from_ne_bytes([b[0], b[1]]))
            .collect();
        assert_eq!((odd.samples::<u16>(), odd.byte_len()), (&expected[..], 12));
        assert!(MappedPlane::map(&file, &path, (0, 0), len, 2).is_none());
        // The last plane ends where the file does.
        let last = MappedPlane::map(&file, &path, (8222, 12), len, 2).unwrap();
        assert_eq!(last.samples::<u16>()[5], 17000);
    }
}
