//! The arithmetic the pyramid and statistics need on each voxel sample type ([`SampleType`],
//! defined once in `residency-schemas`), and [`PlaneOut`], a plane of any of them that a
//! source fills.

use std::fmt;

pub use residency_schemas::SampleType;

/// Number of fine histogram keys. Every sample maps to a key in `0..FINE_KEYS`, monotone in
/// its value; brick histograms are counted on keys and grouped into bins at the end of the pass.
pub const FINE_KEYS: usize = 4096;

/// A voxel sample type, with the exact arithmetic the pyramid and statistics need.
pub trait Sample:
    Copy
    + bytemuck::Pod
    + Send
    + Sync
    + PartialOrd
    + PartialEq
    + Default
    + fmt::Debug
    + zarrs::array::Element
    + zarrs::array::ElementOwned
    + serde::Serialize
    + serde::de::DeserializeOwned
    + 'static
{
    /// The format tag of this type.
    const FORMAT: SampleType;
    /// Smallest representable value (minus infinity for floats): the identity of `max`.
    const LOWEST: Self;
    /// Largest representable value (infinity for floats): the identity of `min`.
    const HIGHEST: Self;
    /// Whether some values (NaN) do not count towards means: when false, the pyramid counts
    /// the level-0 voxels under a voxel from the geometry instead of voxel by voxel.
    const HAS_NAN: bool;
    /// Exact accumulator for sums of many samples.
    type Sum: SumOf<Self::Sum> + serde::Serialize + serde::de::DeserializeOwned;
    /// A narrower exact accumulator, for sums of at most [`Sample::NARROW_TERMS`] samples:
    /// 32 bits for samples of at most 16 bits (half the memory of [`Sample::Sum`], twice the
    /// sums per vector instruction); [`Sample::Sum`] itself for the others.
    type Narrow: SumOf<Self::Sum>;
    /// How many samples a [`Sample::Narrow`] sum holds without overflow, whatever their
    /// values (0: the type has no narrower sum).
    const NARROW_TERMS: u64;

    /// This sample as a sum term (0 for NaN).
    fn to_sum(self) -> Self::Sum;
    /// Whether the sample counts towards means and statistics (false only for NaN).
    fn counts(self) -> bool;
    /// The mean `sum / count`, rounded to nearest once (halves away from zero) for integers.
    /// A zero count gives NaN for floats and 0 for integers.
    fn from_mean(sum: Self::Sum, count: u32) -> Self;
    /// [`Sample::from_mean`] of each sum in `sums` (wide or narrow) over the same `count`,
    /// into `out`.
    #[inline]
    fn means<S: SumOf<Self::Sum>>(out: &mut [Self], sums: &[S], count: u32) {
        for (o, &s) in out.iter_mut().zip(sums) {
            *o = Self::from_mean(s.widened(), count);
        }
    }
    /// The sum as f64 (for statistics).
    fn sum_to_f64(sum: Self::Sum) -> f64;
    /// The value as f64.
    fn to_f64(self) -> f64;
    /// Converts a value of a narrower format exactly (see [`SampleType::promote`]).
    fn from_f64(v: f64) -> Self;
    /// The fine histogram key of this value, in `0..FINE_KEYS`.
    fn key(self) -> usize;
    /// The smallest value whose key is `key` (`key == FINE_KEYS` gives the exclusive upper
    /// bound of the last key, which may be infinite).
    fn key_lower_edge(key: usize) -> f64;
    /// Decodes one sample from bytes in the given byte order.
    fn from_bytes(bytes: &[u8], big_endian: bool) -> Self;
    /// Whether the sample is bit-for-bit the fill value 0 (so `-0.0` is not).
    fn is_fill(self) -> bool;
    /// For formats of at most 16 bits, the value's index in an exact 65536-entry histogram.
    fn exact_index(self) -> Option<usize>;
    /// The value of an exact-histogram index (inverse of [`Sample::exact_index`]).
    fn exact_value(index: usize) -> f64;
    /// Wraps a slice of this type as a source's plane destination.
    fn plane_out(out: &mut [Self]) -> PlaneOut<'_>;
}

/// A type exact sums of samples are kept in, beside the wide one `W` ([`Sample::Sum`]): `W`
/// itself, or a narrower type for sums of few enough terms ([`Sample::Narrow`]).
pub trait SumOf<W>:
    Copy + Send + Sync + Default + PartialEq + std::ops::AddAssign + fmt::Debug + 'static
{
    /// The wide sum `wide` in this type: exact when it fits, which the pyramid's plan makes
    /// sure of (see [`Sample::NARROW_TERMS`]).
    fn narrowed(wide: W) -> Self;
    /// This sum in the wide type, exactly.
    fn widened(self) -> W;
}

/// A wide sum, as its own narrow sum.
macro_rules! wide_sum {
    ($t:ty) => {
        impl SumOf<$t> for $t {
            #[inline]
            fn narrowed(wide: $t) -> Self {
                wide
            }
            #[inline]
            fn widened(self) -> $t {
                self
            }
        }
    };
}

wide_sum!(i64);
wide_sum!(f64);

/// A 32-bit narrow sum of integer samples, beside their `i64` wide sum.
macro_rules! narrow_integer_sum {
    ($t:ty) => {
        impl SumOf<i64> for $t {
            #[inline]
            fn narrowed(wide: i64) -> Self {
                wide as $t
            }
            #[inline]
            fn widened(self) -> i64 {
                i64::from(self)
            }
        }
    };
}

narrow_integer_sum!(u32);
narrow_integer_sum!(i32);

/// The smaller of two samples (`a` when they are unordered).
#[inline]
pub(crate) fn min_of<T: Sample>(a: T, b: T) -> T {
    if b < a { b } else { a }
}

/// The larger of two samples (`a` when they are unordered).
#[inline]
pub(crate) fn max_of<T: Sample>(a: T, b: T) -> T {
    if b > a { b } else { a }
}

/// [`round_mean`] of each of `sums` over `count`, converted by `to`: a power-of-two count
/// (every interior voxel of a pyramid level) rounds with a shift, which gives the same value
/// as the division.
#[multiversion::multiversion(targets("x86_64+avx2"))]
fn round_means<S: SumOf<i64>, T>(sums: &[S], count: u32, out: &mut [T], to: impl Fn(i64) -> T) {
    const SAFE: u64 = 1 << 60;
    if !count.is_power_of_two() || sums.iter().any(|s| s.widened().unsigned_abs() >= SAFE) {
        for (o, &s) in out.iter_mut().zip(sums) {
            *o = to(round_mean(s.widened(), count));
        }
        return;
    }
    let (c, shift) = (i64::from(count), count.trailing_zeros() + 1);
    for (o, s) in out.iter_mut().zip(sums) {
        let s = s.widened();
        // (2|s| + c) / 2c, the sign put back: halves away from zero, as `round_mean`.
        let r = (2 * s.abs() + c) >> shift;
        *o = to(if s < 0 { -r } else { r });
    }
}

fn round_mean(sum: i64, count: u32) -> i64 {
    if count == 0 {
        return 0;
    }
    const SAFE: i64 = 1 << 61;
    if sum.abs() < SAFE {
        let c = count as i64;
        return if sum >= 0 {
            (2 * sum + c) / (2 * c)
        } else {
            -((-2 * sum + c) / (2 * c))
        };
    }
    let (s, c) = (sum as i128, count as i128);
    let r = if s >= 0 {
        (2 * s + c) / (2 * c)
    } else {
        -((-2 * s + c) / (2 * c))
    };
    r as i64
}

macro_rules! int_sample {
    ($t:ty, $fmt:ident, $narrow:ty, $terms:expr, $key:expr, $edge:expr, $exact:expr, $exact_value:expr) => {
        impl Sample for $t {
            fn plane_out(out: &mut [Self]) -> PlaneOut<'_> {
                PlaneOut::$fmt(out)
            }
            #[inline]
            fn exact_index(self) -> Option<usize> {
                let f: fn($t) -> Option<usize> = $exact;
                f(self)
            }
            fn exact_value(index: usize) -> f64 {
                let f: fn(usize) -> f64 = $exact_value;
                f(index)
            }
            const FORMAT: SampleType = SampleType::$fmt;
            const LOWEST: Self = <$t>::MIN;
            const HIGHEST: Self = <$t>::MAX;
            const HAS_NAN: bool = false;
            type Sum = i64;
            type Narrow = $narrow;
            const NARROW_TERMS: u64 = $terms;
            #[inline]
            fn to_sum(self) -> i64 {
                self as i64
            }
            #[inline]
            fn counts(self) -> bool {
                true
            }
            #[inline]
            fn from_mean(sum: i64, count: u32) -> Self {
                round_mean(sum, count) as $t
            }
            #[inline]
            fn means<S: SumOf<i64>>(out: &mut [Self], sums: &[S], count: u32) {
                round_means(sums, count, out, |m| m as $t);
            }
            fn sum_to_f64(sum: i64) -> f64 {
                sum as f64
            }
            #[inline]
            fn to_f64(self) -> f64 {
                self as f64
            }
            fn from_f64(v: f64) -> Self {
                v as $t
            }
            #[inline]
            fn key(self) -> usize {
                let f: fn($t) -> usize = $key;
                f(self)
            }
            fn key_lower_edge(key: usize) -> f64 {
                let f: fn(usize) -> f64 = $edge;
                f(key)
            }
            #[inline]
            fn is_fill(self) -> bool {
                self == 0
            }
            #[inline]
            fn from_bytes(b: &[u8], big_endian: bool) -> Self {
                let a = b.try_into().expect("sample width");
                if big_endian {
                    <$t>::from_be_bytes(a)
                } else {
                    <$t>::from_le_bytes(a)
                }
            }
        }
    };
}

int_sample!(
    u8,
    U8,
    u32,
    u32::MAX as u64 / u8::MAX as u64,
    |v| v as usize * 16,
    |k| k.div_ceil(16) as f64,
    |v| Some(v as usize),
    |i| i as f64
);
int_sample!(
    u16,
    U16,
    u32,
    u32::MAX as u64 / u16::MAX as u64,
    |v| (v >> 4) as usize,
    |k| (k * 16) as f64,
    |v| Some(v as usize),
    |i| i as f64
);
int_sample!(
    i16,
    I16,
    i32,
    1 << 16,
    |v| ((v as i32 + 32768) >> 4) as usize,
    |k| (k as f64) * 16.0 - 32768.0,
    |v| Some((v as i32 + 32768) as usize),
    |i| i as f64 - 32768.0
);
int_sample!(
    u32,
    U32,
    i64,
    0,
    |v| (v >> 20) as usize,
    |k| (k as f64) * 1048576.0,
    |_| None,
    |i| i as f64
);
int_sample!(
    i32,
    I32,
    i64,
    0,
    |v| ((v as i64 + 2147483648) >> 20) as usize,
    |k| (k as f64) * 1048576.0 - 2147483648.0,
    |_| None,
    |i| i as f64
);

/// Order-preserving map of f32 bits to u32.
fn f32_order_key(v: f32) -> u32 {
    let b = v.to_bits();
    if b & 0x8000_0000 != 0 {
        !b
    } else {
        b | 0x8000_0000
    }
}

impl Sample for f32 {
    const FORMAT: SampleType = SampleType::F32;
    fn plane_out(out: &mut [Self]) -> PlaneOut<'_> {
        PlaneOut::F32(out)
    }
    const LOWEST: Self = f32::NEG_INFINITY;
    const HIGHEST: Self = f32::INFINITY;
    const HAS_NAN: bool = true;
    type Sum = f64;
    type Narrow = f64;
    const NARROW_TERMS: u64 = 0;
    #[inline]
    fn to_sum(self) -> f64 {
        if self.is_nan() { 0.0 } else { self as f64 }
    }
    #[inline]
    fn counts(self) -> bool {
        !self.is_nan()
    }
    #[inline]
    fn from_mean(sum: f64, count: u32) -> Self {
        if count == 0 {
            f32::NAN
        } else {
            (sum / count as f64) as f32
        }
    }
    fn sum_to_f64(sum: f64) -> f64 {
        sum
    }
    #[inline]
    fn to_f64(self) -> f64 {
        self as f64
    }
    fn from_f64(v: f64) -> Self {
        v as f32
    }
    #[inline]
    fn key(self) -> usize {
        (f32_order_key(self) >> 20) as usize
    }
    fn key_lower_edge(key: usize) -> f64 {
        if key >= FINE_KEYS {
            return f64::INFINITY;
        }
        let k = (key as u32) << 20;
        let bits = if k & 0x8000_0000 != 0 {
            k & 0x7fff_ffff
        } else {
            !k
        };
        let v = f32::from_bits(bits);
        if v.is_nan() {
            if key < FINE_KEYS / 2 {
                f64::NEG_INFINITY
            } else {
                f64::INFINITY
            }
        } else {
            v as f64
        }
    }
    #[inline]
    fn is_fill(self) -> bool {
        self.to_bits() == 0
    }
    fn exact_index(self) -> Option<usize> {
        None
    }
    fn exact_value(index: usize) -> f64 {
        index as f64
    }
    #[inline]
    fn from_bytes(b: &[u8], big_endian: bool) -> Self {
        let a = b.try_into().expect("sample width");
        if big_endian {
            f32::from_be_bytes(a)
        } else {
            f32::from_le_bytes(a)
        }
    }
}

/// Calls `$body` with the type alias `$T` bound to the Rust type of `$format`.
#[macro_export]
macro_rules! with_sample_type {
    ($format:expr, $T:ident => $body:expr) => {
        match $format {
            $crate::sample_format::SampleType::U8 => {
                type $T = u8;
                $body
            }
            $crate::sample_format::SampleType::U16 => {
                type $T = u16;
                $body
            }
            $crate::sample_format::SampleType::I16 => {
                type $T = i16;
                $body
            }
            $crate::sample_format::SampleType::U32 => {
                type $T = u32;
                $body
            }
            $crate::sample_format::SampleType::I32 => {
                type $T = i32;
                $body
            }
            $crate::sample_format::SampleType::F32 => {
                type $T = f32;
                $body
            }
        }
    };
}

/// Where a source writes one z-plane of one channel (`y, x` in C order): a slice of the
/// converter's sample type, which the source fills converting exactly from its own format.
pub enum PlaneOut<'a> {
    /// 8-bit unsigned destination.
    U8(&'a mut [u8]),
    /// 16-bit unsigned destination.
    U16(&'a mut [u16]),
    /// 16-bit signed destination.
    I16(&'a mut [i16]),
    /// 32-bit unsigned destination.
    U32(&'a mut [u32]),
    /// 32-bit signed destination.
    I32(&'a mut [i32]),
    /// 32-bit float destination.
    F32(&'a mut [f32]),
}

impl PlaneOut<'_> {
    /// The destination's sample format.
    pub fn format(&self) -> SampleType {
        match self {
            PlaneOut::U8(_) => SampleType::U8,
            PlaneOut::U16(_) => SampleType::U16,
            PlaneOut::I16(_) => SampleType::I16,
            PlaneOut::U32(_) => SampleType::U32,
            PlaneOut::I32(_) => SampleType::I32,
            PlaneOut::F32(_) => SampleType::F32,
        }
    }

    /// The destination's memory as bytes (samples in native byte order), for decoders that
    /// write samples of the destination's own format straight into it.
    pub fn bytes_mut(&mut self) -> &mut [u8] {
        match self {
            PlaneOut::U8(v) => v,
            PlaneOut::U16(v) => bytemuck::cast_slice_mut(v),
            PlaneOut::I16(v) => bytemuck::cast_slice_mut(v),
            PlaneOut::U32(v) => bytemuck::cast_slice_mut(v),
            PlaneOut::I32(v) => bytemuck::cast_slice_mut(v),
            PlaneOut::F32(v) => bytemuck::cast_slice_mut(v),
        }
    }

    /// Number of samples to write.
    pub fn len(&self) -> usize {
        match self {
            PlaneOut::U8(v) => v.len(),
            PlaneOut::U16(v) => v.len(),
            PlaneOut::I16(v) => v.len(),
            PlaneOut::U32(v) => v.len(),
            PlaneOut::I32(v) => v.len(),
            PlaneOut::F32(v) => v.len(),
        }
    }

    /// Whether there is nothing to write.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Fills the destination from packed samples of `format` in `bytes`: sample `sample` of
    /// every pixel of `samples` interleaved samples. Values are converted exactly (the
    /// converter only asks for promotions that [`SampleType::promote`] allows).
    pub fn fill_from_bytes(
        &mut self,
        bytes: &[u8],
        format: SampleType,
        big_endian: bool,
        samples: usize,
        sample: usize,
    ) {
        fn fill<S: Sample, T: Sample>(
            bytes: &[u8],
            big_endian: bool,
            samples: usize,
            sample: usize,
            out: &mut [T],
        ) {
            let w = S::FORMAT.bytes();
            let stride = w * samples;
            assert_eq!(bytes.len(), out.len() * stride, "decoded plane size");
            let pixels = bytes.chunks_exact(stride);
            if S::FORMAT == T::FORMAT && samples == 1 && big_endian == cfg!(target_endian = "big") {
                // The bytes are the destination's own.
                bytemuck::cast_slice_mut::<T, u8>(out).copy_from_slice(bytes);
            } else if S::FORMAT == T::FORMAT {
                // Same format: decode the bytes as the destination type, bit for bit.
                for (o, px) in out.iter_mut().zip(pixels) {
                    *o = T::from_bytes(&px[sample * w..(sample + 1) * w], big_endian);
                }
            } else {
                for (o, px) in out.iter_mut().zip(pixels) {
                    let s = S::from_bytes(&px[sample * w..(sample + 1) * w], big_endian);
                    *o = T::from_f64(s.to_f64());
                }
            }
        }
        macro_rules! dispatch {
            ($out:expr) => {
                crate::with_sample_type!(format, S => fill::<S, _>(bytes, big_endian, samples, sample, $out))
            };
        }
        match self {
            PlaneOut::U8(v) => dispatch!(v),
            PlaneOut::U16(v) => dispatch!(v),
            PlaneOut::I16(v) => dispatch!(v),
            PlaneOut::U32(v) => dispatch!(v),
            PlaneOut::I32(v) => dispatch!(v),
            PlaneOut::F32(v) => dispatch!(v),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `NARROW_TERMS` samples of the type's extremes sum exactly in its narrow sum, and one
    /// more of one of them would not.
    fn narrow_sums_hold_their_terms<T: Sample<Sum = i64>>() {
        let terms = T::NARROW_TERMS as i64;
        let extremes = [T::LOWEST.to_sum(), T::HIGHEST.to_sum()];
        let exact = |sum: i64| T::Narrow::narrowed(sum).widened() == sum;
        assert!(extremes.iter().all(|e| exact(e * terms)), "{:?}", T::FORMAT);
        assert!(
            !extremes.iter().all(|e| exact(e * (terms + 1))),
            "{:?}",
            T::FORMAT
        );
    }

    #[test]
    fn narrow_sums_are_exact_up_to_their_terms() {
        narrow_sums_hold_their_terms::<u8>();
        narrow_sums_hold_their_terms::<u16>();
        narrow_sums_hold_their_terms::<i16>();
        assert_eq!(
            [u8::NARROW_TERMS, u16::NARROW_TERMS, i16::NARROW_TERMS],
            [16_843_009, 65_537, 65_536]
        );
        // Wider samples have no narrower sum.
        assert_eq!(
            [u32::NARROW_TERMS, i32::NARROW_TERMS, f32::NARROW_TERMS],
            [0; 3]
        );
        // Means of narrow sums are those of the same sums held wide, for every kind of count:
        // the shift (powers of two), the division (edges), halves, the narrow types' extremes.
        let unsigned = [
            0,
            1,
            3,
            4,
            5,
            12,
            65_535 * 65_536,
            u32::MAX - 65_534,
            u32::MAX,
        ];
        let signed = [i32::MIN, i32::MIN + 1, -5, -4, -3, -1, 0, 3, 4, 5, i32::MAX];
        for count in (1..=9).chain([12, 24, 96, 65_536, 65_537]) {
            let (mut narrow, mut wide) = ([0u16; 9], [0u16; 9]);
            u16::means(&mut narrow, &unsigned, count);
            u16::means(&mut wide, &unsigned.map(i64::from), count);
            assert_eq!(narrow, wide, "u16, count {count}");
            let (mut narrow, mut wide) = ([0i16; 11], [0i16; 11]);
            i16::means(&mut narrow, &signed, count);
            i16::means(&mut wide, &signed.map(i64::from), count);
            assert_eq!(narrow, wide, "i16, count {count}");
        }
        let mut u = [0u16; 3];
        u16::means(&mut u, &[u32::MAX - 65_534, 7, 9], 65_536);
        assert_eq!(u, [65_535, 0, 0]);
    }

    #[test]
    fn means_of_a_row_equal_the_mean_of_each_sum() {
        // Powers of two (the shift), other counts (the division), negative sums, halves, and
        // sums too large for the shift.
        let sums: Vec<i64> = (-300..300)
            .chain([i64::MAX / 2, i64::MIN / 2, (1 << 60) + 3, -(1 << 60) - 5])
            .collect();
        for count in [1, 2, 3, 4, 6, 8, 12, 64, 512, 1 << 20, 3 << 20] {
            let mut out = vec![0i64; sums.len()];
            round_means(&sums, count, &mut out, |m| m);
            let each: Vec<i64> = sums.iter().map(|&s| round_mean(s, count)).collect();
            assert_eq!(out, each, "count {count}");
        }
        let mut u = [0u16; 3];
        u16::means(&mut u, &[4, 11, 12], 8);
        assert_eq!(u, [1, 1, 2]);
        let mut f = [0f32; 2];
        f32::means(&mut f, &[3.0, -1.0], 2);
        assert_eq!(f, [1.5, -0.5]);
    }

    #[test]
    fn integer_means_round_half_away_from_zero() {
        assert_eq!(u16::from_mean(5, 2), 3);
        assert_eq!(u16::from_mean(4, 3), 1);
        assert_eq!(u16::from_mean(5, 3), 2);
        assert_eq!(i16::from_mean(-5, 2), -3);
        assert_eq!(i16::from_mean(-4, 3), -1);
        assert_eq!(u32::from_mean(u32::MAX as i64 * 8, 8), u32::MAX);
    }

    #[test]
    fn keys_are_monotone_and_edges_bound_them() {
        let vals = [
            f32::NEG_INFINITY,
            -1e30,
            -1.5,
            -1e-40,
            0.0,
            1e-40,
            1.0,
            3.5,
            1e30,
            f32::INFINITY,
        ];
        for w in vals.windows(2) {
            assert!(w[0].key() <= w[1].key(), "{w:?}");
        }
        for v in vals {
            let k = v.key();
            assert!(f32::key_lower_edge(k) <= v as f64, "{v}");
            // +inf sits in the last key, whose upper edge is +inf itself (closed there).
            assert!(
                (v as f64) < f32::key_lower_edge(k + 1) || v == f32::INFINITY,
                "{v}"
            );
        }
        for v in [0u16, 15, 16, 65535] {
            let k = v.key();
            assert!(u16::key_lower_edge(k) <= v as f64 && (v as f64) < u16::key_lower_edge(k + 1));
        }
        for v in [i16::MIN, -1, 0, i16::MAX] {
            let k = v.key();
            assert!(i16::key_lower_edge(k) <= v as f64 && (v as f64) < i16::key_lower_edge(k + 1));
        }
        for v in [0u8, 1, 255] {
            let k = v.key();
            assert_eq!(u8::key_lower_edge(k), v as f64);
        }
    }
}
