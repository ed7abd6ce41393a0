//! Planes lent by their file ([`MappedPlane`]): a plane stored uncompressed, in the sample
//! type and byte order the converter works in, is the page cache's own memory mapped
//! read-only, so the converter reads it where it lies instead of copying it into a slab.

use std::fs::File;
use std::path::Path;

use memmap2::{Mmap, MmapOptions};

use super::error::SourceError;
use crate::sample_format::Sample;

/// One whole plane of an input, mapped from its file.
///
/// Mapping assumes the file does not change while the plane is mapped: a file truncated under
/// a conversion ends it with `SIGBUS` instead of an error, so a conversion of inputs that may
/// change reads them instead (`ConvertOptions::map_inputs`).
pub struct MappedPlane {
    map: Mmap,
    /// Where the plane starts in `map` (the mapping starts on a page boundary).
    start: usize,
    /// Bytes of the plane.
    len: usize,
}

impl MappedPlane {
    /// Maps `len` bytes at `offset` of `file` (`path`, `file_len` bytes long), with its page
    /// table filled now ([`MmapOptions::populate`]): the mapping thread, not the converter's
    /// workers, waits for the disk and takes the page faults. None when the bytes do not lie
    /// inside the file or do not start on a multiple of `align`, the samples' alignment (a
    /// plane that cannot be used in place is read instead).
    ///
    /// # Errors
    /// When the system refuses the mapping.
    pub(crate) fn map(
        file: &File,
        path: &Path,
        (offset, len): (u64, u64),
        file_len: u64,
        align: usize,
    ) -> Result<Option<Self>, SourceError> {
        let page = page_size();
        let inside = offset.checked_add(len).is_some_and(|end| end <= file_len);
        if !inside || len == 0 || !offset.is_multiple_of(align as u64) {
            return Ok(None);
        }
        let base = offset / page * page;
        let start = (offset - base) as usize;
        let (Ok(len), Ok(mapped)) = (usize::try_from(len), usize::try_from(len + offset - base))
        else {
            return Ok(None);
        };
        // SAFETY: the mapping is read-only and lies inside the file (checked above). Its
        // contents change only if another process writes the file during the conversion,
        // which `MappedPlane`'s documentation rules out.
        let map = unsafe {
            MmapOptions::new()
                .offset(base)
                .len(mapped)
                .populate()
                .map(file)
        }
        .map_err(|source| SourceError::Map {
            path: path.to_path_buf(),
            offset,
            source,
        })?;
        Ok(Some(Self { map, start, len }))
    }

    /// The plane's samples.
    ///
    /// # Panics
    /// When `T` is not the sample type the plane was mapped for (its alignment or size do not
    /// fit): a converter bug.
    pub fn samples<T: Sample>(&self) -> &[T] {
        bytemuck::cast_slice(&self.map[self.start..self.start + self.len])
    }
}

/// The system's memory page size in bytes.
fn page_size() -> u64 {
    // SAFETY: `sysconf` only reads a system configuration value.
    let size = unsafe { libc::sysconf(libc::_SC_PAGESIZE) };
    u64::try_from(size).ok().filter(|&s| s > 0).unwrap_or(4096)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_plane_is_lent_where_it_lies_and_refused_outside_the_file_or_misaligned() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("planes.raw");
        // 8198 bytes of header (more than a page), then 3 planes of 2 × 3 u16.
        let mut bytes = vec![0xAAu8; 8198];
        bytes.extend((0u16..18).flat_map(|v| (v * 1000).to_le_bytes()));
        std::fs::write(&path, &bytes).unwrap();
        let file = File::open(&path).unwrap();
        let len = bytes.len() as u64;
        // The second plane: 12 bytes at 8198 + 12, across no page boundary.
        let plane = MappedPlane::map(&file, &path, (8210, 12), len, 2)
            .unwrap()
            .unwrap();
        assert_eq!(
            plane.samples::<u16>(),
            &[6000, 7000, 8000, 9000, 10000, 11000]
        );
        // A plane past the end of the file, or at an odd offset, is read instead.
        assert!(
            MappedPlane::map(&file, &path, (8222, 14), len, 2)
                .unwrap()
                .is_none()
        );
        assert!(
            MappedPlane::map(&file, &path, (8199, 12), len, 2)
                .unwrap()
                .is_none()
        );
        assert!(
            MappedPlane::map(&file, &path, (0, 0), len, 2)
                .unwrap()
                .is_none()
        );
        // The last plane ends where the file does.
        let last = MappedPlane::map(&file, &path, (8222, 12), len, 2)
            .unwrap()
            .unwrap();
        assert_eq!(last.samples::<u16>()[5], 17000);
    }
}
