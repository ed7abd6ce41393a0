//! A small TIFF writer: classic or BigTIFF, either byte order, any tags with any values, data
//! blobs placed where the caller says. It writes exactly what it is given, so a structured
//! fuzz input can describe well-formed files and files whose tags lie.

/// TIFF field types used here.
pub mod ty {
    /// 8-bit unsigned.
    pub const BYTE: u16 = 1;
    /// NUL-terminated 7-bit text.
    pub const ASCII: u16 = 2;
    /// 16-bit unsigned.
    pub const SHORT: u16 = 3;
    /// 32-bit unsigned.
    pub const LONG: u16 = 4;
    /// Two LONGs: numerator, denominator.
    pub const RATIONAL: u16 = 5;
    /// 64-bit unsigned (BigTIFF).
    pub const LONG8: u16 = 16;
}

/// Tags used here.
pub mod tag {
    /// ImageWidth.
    pub const IMAGE_WIDTH: u16 = 256;
    /// ImageLength.
    pub const IMAGE_LENGTH: u16 = 257;
    /// BitsPerSample.
    pub const BITS_PER_SAMPLE: u16 = 258;
    /// Compression.
    pub const COMPRESSION: u16 = 259;
    /// PhotometricInterpretation.
    pub const PHOTOMETRIC: u16 = 262;
    /// ImageDescription.
    pub const IMAGE_DESCRIPTION: u16 = 270;
    /// StripOffsets.
    pub const STRIP_OFFSETS: u16 = 273;
    /// SamplesPerPixel.
    pub const SAMPLES_PER_PIXEL: u16 = 277;
    /// RowsPerStrip.
    pub const ROWS_PER_STRIP: u16 = 278;
    /// StripByteCounts.
    pub const STRIP_BYTE_COUNTS: u16 = 279;
    /// XResolution.
    pub const X_RESOLUTION: u16 = 282;
    /// YResolution.
    pub const Y_RESOLUTION: u16 = 283;
    /// PlanarConfiguration.
    pub const PLANAR_CONFIGURATION: u16 = 284;
    /// Predictor.
    pub const PREDICTOR: u16 = 317;
    /// TileWidth.
    pub const TILE_WIDTH: u16 = 322;
    /// TileLength.
    pub const TILE_LENGTH: u16 = 323;
    /// TileOffsets.
    pub const TILE_OFFSETS: u16 = 324;
    /// TileByteCounts.
    pub const TILE_BYTE_COUNTS: u16 = 325;
    /// SampleFormat.
    pub const SAMPLE_FORMAT: u16 = 339;
}

/// One directory entry: a tag, its field type, its value count and its value bytes (in the
/// file's byte order; see [`Tiff::shorts`] and friends).
#[derive(Clone, Debug)]
pub struct Entry {
    /// Tag number.
    pub tag: u16,
    /// Field type.
    pub ty: u16,
    /// Value count as written (need not match `bytes`).
    pub count: u64,
    /// The value bytes, written inline when they fit and out of line otherwise.
    pub bytes: Vec<u8>,
}

/// A TIFF file under construction.
pub struct Tiff {
    big_endian: bool,
    bigtiff: bool,
    out: Vec<u8>,
    ifds: Vec<Vec<Entry>>,
}

impl Tiff {
    /// An empty file with its header.
    pub fn new(big_endian: bool, bigtiff: bool) -> Self {
        let mut t = Self {
            big_endian,
            bigtiff,
            out: Vec::new(),
            ifds: Vec::new(),
        };
        t.out
            .extend_from_slice(if big_endian { b"MM" } else { b"II" });
        if bigtiff {
            t.put16(43);
            t.put16(8);
            t.put16(0);
            t.put64(0);
        } else {
            t.put16(42);
            t.put32(0);
        }
        t
    }

    fn put16(&mut self, v: u16) {
        let b = if self.big_endian {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        };
        self.out.extend_from_slice(&b);
    }

    fn put32(&mut self, v: u32) {
        let b = if self.big_endian {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        };
        self.out.extend_from_slice(&b);
    }

    fn put64(&mut self, v: u64) {
        let b = if self.big_endian {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        };
        self.out.extend_from_slice(&b);
    }

    fn put_offset(&mut self, v: u64) {
        if self.bigtiff {
            self.put64(v)
        } else {
            self.put32(v as u32)
        }
    }

    fn patch_offset(&mut self, at: usize, v: u64) {
        let b: Vec<u8> = match (self.bigtiff, self.big_endian) {
            (true, true) => v.to_be_bytes().to_vec(),
            (true, false) => v.to_le_bytes().to_vec(),
            (false, true) => (v as u32).to_be_bytes().to_vec(),
            (false, false) => (v as u32).to_le_bytes().to_vec(),
        };
        self.out[at..at + b.len()].copy_from_slice(&b);
    }

    /// Whether this is a BigTIFF.
    pub fn is_bigtiff(&self) -> bool {
        self.bigtiff
    }

    /// Appends a data blob (strip or tile bytes) and returns its offset.
    pub fn blob(&mut self, bytes: &[u8]) -> u64 {
        let at = self.out.len() as u64;
        self.out.extend_from_slice(bytes);
        at
    }

    /// Current length of the file.
    pub fn len(&self) -> u64 {
        self.out.len() as u64
    }

    /// Whether nothing but the header has been written.
    pub fn is_empty(&self) -> bool {
        false
    }

    /// An entry of SHORT values.
    pub fn shorts(&self, tag: u16, values: &[u16]) -> Entry {
        let mut bytes = Vec::new();
        for v in values {
            bytes.extend(if self.big_endian {
                v.to_be_bytes()
            } else {
                v.to_le_bytes()
            });
        }
        Entry {
            tag,
            ty: ty::SHORT,
            count: values.len() as u64,
            bytes,
        }
    }

    /// An entry of LONG values.
    pub fn longs(&self, tag: u16, values: &[u32]) -> Entry {
        let mut bytes = Vec::new();
        for v in values {
            bytes.extend(if self.big_endian {
                v.to_be_bytes()
            } else {
                v.to_le_bytes()
            });
        }
        Entry {
            tag,
            ty: ty::LONG,
            count: values.len() as u64,
            bytes,
        }
    }

    /// An entry of offsets or byte counts: LONG8 in a BigTIFF, LONG (truncated) otherwise.
    pub fn offsets(&self, tag: u16, values: &[u64]) -> Entry {
        if self.bigtiff {
            let mut bytes = Vec::new();
            for v in values {
                bytes.extend(if self.big_endian {
                    v.to_be_bytes()
                } else {
                    v.to_le_bytes()
                });
            }
            Entry {
                tag,
                ty: ty::LONG8,
                count: values.len() as u64,
                bytes,
            }
        } else {
            let v: Vec<u32> = values.iter().map(|&v| v as u32).collect();
            self.longs(tag, &v)
        }
    }

    /// An entry of one RATIONAL.
    pub fn rational(&self, tag: u16, n: u32, d: u32) -> Entry {
        let mut e = self.longs(tag, &[n, d]);
        e.ty = ty::RATIONAL;
        e.count = 1;
        e
    }

    /// An ASCII entry (NUL-terminated here).
    pub fn ascii(&self, tag: u16, text: &[u8]) -> Entry {
        let mut bytes = text.to_vec();
        bytes.push(0);
        Entry {
            tag,
            ty: ty::ASCII,
            count: bytes.len() as u64,
            bytes,
        }
    }

    /// Adds a directory (written in the order added, each linked to the next).
    pub fn ifd(&mut self, entries: Vec<Entry>) {
        self.ifds.push(entries);
    }

    /// Writes the directories and returns the file.
    pub fn finish(mut self) -> Vec<u8> {
        let first_at = if self.bigtiff { 8 } else { 4 };
        let mut link_at = first_at;
        let ifds = std::mem::take(&mut self.ifds);
        for entries in ifds {
            if self.out.len() % 2 == 1 {
                self.out.push(0);
            }
            let here = self.out.len() as u64;
            self.patch_offset(link_at, here);
            let inline = if self.bigtiff { 8 } else { 4 };
            if self.bigtiff {
                self.put64(entries.len() as u64);
            } else {
                self.put16(entries.len() as u16);
            }
            let mut pending = Vec::new();
            for e in &entries {
                self.put16(e.tag);
                self.put16(e.ty);
                if self.bigtiff {
                    self.put64(e.count)
                } else {
                    self.put32(e.count as u32)
                }
                if e.bytes.len() <= inline {
                    let mut b = e.bytes.clone();
                    b.resize(inline, 0);
                    self.out.extend_from_slice(&b);
                } else {
                    pending.push((self.out.len(), e.bytes.clone()));
                    self.put_offset(0);
                }
            }
            link_at = self.out.len();
            self.put_offset(0);
            for (at, bytes) in pending {
                if self.out.len() % 2 == 1 {
                    self.out.push(0);
                }
                let off = self.out.len() as u64;
                self.patch_offset(at, off);
                self.out.extend_from_slice(&bytes);
            }
        }
        self.out
    }
}
