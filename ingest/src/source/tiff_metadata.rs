//! Stack metadata embedded in TIFF files: ImageJ hyperstack descriptions and OME-XML.

use std::num::ParseIntError;

/// OME-XML that does not describe a stack ingest can read. The messages name the element or
/// attribute at fault; the file is named by the [`SourceError`](super::SourceError) around it.
#[derive(Debug, thiserror::Error)]
pub enum OmeXmlError {
    /// Not well-formed XML.
    #[error("invalid OME-XML")]
    Invalid(#[source] roxmltree::Error),
    /// No `Pixels` element anywhere in the document.
    #[error("OME-XML has no Pixels element")]
    NoPixels,
    /// A size attribute of `Pixels` is missing.
    #[error("OME-XML Pixels has no {name}")]
    MissingSize {
        /// The attribute (`SizeZ`, `SizeC` or `SizeT`).
        name: &'static str,
    },
    /// A size attribute of `Pixels` is not a whole number.
    #[error("OME-XML Pixels {name} is not a number")]
    BadSize {
        /// The attribute (`SizeZ`, `SizeC` or `SizeT`).
        name: &'static str,
        /// Why it does not parse.
        #[source]
        source: ParseIntError,
    },
    /// A `DimensionOrder` that is not `XY` followed by three axes.
    #[error("OME-XML DimensionOrder '{order}' is not one of XY[ZCT permutation]")]
    BadOrder {
        /// The order as given.
        order: String,
    },
    /// A `DimensionOrder` naming an axis other than `Z`, `C` or `T`.
    #[error("OME-XML DimensionOrder '{order}' has an unknown axis '{axis}'")]
    UnknownAxis {
        /// The order as given.
        order: String,
        /// The unknown axis.
        axis: char,
    },
    /// Sizes whose product, the page count, passes 2^64.
    #[error("OME-XML Pixels SizeZ {z} x SizeC {c} x SizeT {t} is more than 2^64 planes")]
    TooManyPlanes {
        /// `SizeZ`.
        z: u64,
        /// `SizeC`.
        c: u64,
        /// `SizeT`.
        t: u64,
    },
}

/// How a multi-page TIFF maps (channel, z) to pages, plus physical metadata.
#[derive(Clone, Debug, PartialEq)]
pub struct StackLayout {
    /// Number of channel planes (pages per z that hold different channels).
    pub channel_planes: usize,
    /// Number of z planes.
    pub depth: u64,
    /// Page-index step between consecutive channel planes.
    pub channel_stride: u64,
    /// Page-index step between consecutive z planes.
    pub z_stride: u64,
    /// Number of time points (only the first is read).
    pub time_points: u64,
    /// Voxel size `z, y, x`, where known (`y, x` may be filled from resolution tags later).
    pub voxel_size: [Option<f64>; 3],
    /// Physical unit name (OME-Zarr / UDUNITS spelling).
    pub unit: Option<String>,
    /// Channel names, when given.
    pub channel_names: Vec<String>,
}

/// Maps a unit spelling found in microscopy metadata to the OME-Zarr (UDUNITS-2) name.
pub fn normalise_unit(unit: &str) -> Option<String> {
    let u = unit.trim();
    let name = match u {
        "µm" | "μm" | "um" | "micron" | "microns" | "micrometer" | "micrometre" | "\\u00B5m" => {
            "micrometer"
        }
        "nm" | "nanometer" | "nanometre" => "nanometer",
        "mm" | "millimeter" | "millimetre" => "millimeter",
        "cm" | "centimeter" | "centimetre" => "centimeter",
        "m" | "meter" | "metre" => "meter",
        "Å" | "angstrom" | "A" => "angstrom",
        "pm" | "picometer" => "picometer",
        "inch" | "in" => "inch",
        _ => return None,
    };
    Some(name.to_string())
}

/// Parses an ImageJ `ImageDescription` (`ImageJ=...` key=value lines).
pub fn parse_imagej(description: &str) -> Option<StackLayout> {
    if !description.starts_with("ImageJ=") {
        return None;
    }
    let get = |key: &str| {
        description.lines().find_map(|l| {
            let (k, v) = l.split_once('=')?;
            (k.trim() == key).then(|| v.trim().to_string())
        })
    };
    let num = |key: &str| get(key).and_then(|v| v.parse::<u64>().ok());
    let channels = num("channels").unwrap_or(1).max(1);
    let frames = num("frames").unwrap_or(1).max(1);
    let images = num("images").unwrap_or(1);
    // Found by fuzzing: `channels * frames` overflowed (and, wrapped to 0, divided by zero).
    let slices = num("slices").unwrap_or_else(|| {
        channels
            .checked_mul(frames)
            .map_or(1, |planes| (images / planes).max(1))
    });
    Some(StackLayout {
        channel_planes: channels as usize,
        depth: slices,
        channel_stride: 1,
        z_stride: channels,
        time_points: frames,
        voxel_size: [get("spacing").and_then(|v| v.parse().ok()), None, None],
        unit: get("unit").and_then(|u| normalise_unit(&u)),
        channel_names: Vec::new(),
    })
}

/// Parses OME-XML (the `ImageDescription` of the first page of an OME-TIFF).
///
/// # Errors
/// When the XML is not well-formed, has no `Pixels` element or no numeric `SizeZ`, `SizeC`
/// and `SizeT`, its `DimensionOrder` is not an `XY[ZCT]` permutation, or the sizes multiply
/// past 2^64 pages.
pub fn parse_ome_xml(xml: &str) -> Result<StackLayout, OmeXmlError> {
    let doc = roxmltree::Document::parse(xml).map_err(OmeXmlError::Invalid)?;
    let pixels = doc
        .descendants()
        .find(|n| n.has_tag_name("Pixels") || n.tag_name().name() == "Pixels")
        .ok_or(OmeXmlError::NoPixels)?;
    let size = |name: &'static str| -> Result<u64, OmeXmlError> {
        pixels
            .attribute(name)
            .ok_or(OmeXmlError::MissingSize { name })?
            .parse()
            .map_err(|source| OmeXmlError::BadSize { name, source })
    };
    let (z, c, t) = (size("SizeZ")?, size("SizeC")?, size("SizeT")?);
    let order = pixels.attribute("DimensionOrder").unwrap_or("XYZCT");
    let channels: Vec<_> = pixels
        .children()
        .filter(|n| n.tag_name().name() == "Channel")
        .collect();
    let samples_per_pixel: u64 = channels
        .first()
        .and_then(|ch| ch.attribute("SamplesPerPixel"))
        .and_then(|s| s.parse().ok())
        .unwrap_or(1)
        .max(1);
    let channel_planes = (c / samples_per_pixel).max(1);
    let mut stride = 1u64;
    let (mut z_stride, mut c_stride) = (0, 0);
    if !order.starts_with("XY") || order.len() != 5 {
        return Err(OmeXmlError::BadOrder {
            order: order.to_string(),
        });
    }
    for axis in order[2..].chars() {
        let size = match axis {
            'Z' => {
                z_stride = stride;
                z
            }
            'C' => {
                c_stride = stride;
                channel_planes
            }
            'T' => t,
            _ => {
                return Err(OmeXmlError::UnknownAxis {
                    order: order.to_string(),
                    axis,
                });
            }
        };
        // The product of the sizes may overflow (as ImageJ's did under fuzzing).
        stride = stride
            .checked_mul(size)
            .ok_or(OmeXmlError::TooManyPlanes { z, c, t })?;
    }
    let physical = |axis: &str| -> Option<f64> {
        pixels
            .attribute(format!("PhysicalSize{axis}").as_str())
            .and_then(|v| v.parse().ok())
    };
    let unit = pixels
        .attribute("PhysicalSizeXUnit")
        .map_or(Some("micrometer".to_string()), normalise_unit);
    Ok(StackLayout {
        channel_planes: channel_planes as usize,
        depth: z,
        channel_stride: c_stride,
        z_stride,
        time_points: t,
        voxel_size: [physical("Z"), physical("Y"), physical("X")],
        unit,
        channel_names: channels
            .iter()
            .enumerate()
            .map(|(i, ch)| {
                ch.attribute("Name")
                    .map_or(format!("Channel {i}"), str::to_string)
            })
            .collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn imagej_hyperstack_order_is_czt() {
        let l = parse_imagej(
            "ImageJ=1.11a\nimages=24\nchannels=3\nslices=8\nhyperstack=true\nmode=grayscale\nunit=micron\nspacing=2.5\nloop=false\n",
        )
        .unwrap();
        assert_eq!(l.channel_planes, 3);
        assert_eq!(l.depth, 8);
        assert_eq!((l.channel_stride, l.z_stride), (1, 3));
        assert_eq!(l.voxel_size[0], Some(2.5));
        assert_eq!(l.unit.as_deref(), Some("micrometer"));
        assert!(parse_imagej("not imagej").is_none());
    }

    #[test]
    fn ome_dimension_orders() {
        let xml = |order: &str| {
            format!(
                r#"<?xml version="1.0"?><OME xmlns="http://www.openmicroscopy.org/Schemas/OME/2016-06"><Image ID="Image:0"><Pixels DimensionOrder="{order}" ID="Pixels:0" SizeC="2" SizeT="1" SizeX="4" SizeY="3" SizeZ="5" Type="uint16" PhysicalSizeX="0.5" PhysicalSizeY="0.5" PhysicalSizeZ="2" PhysicalSizeZUnit="µm"><Channel ID="Channel:0:0" Name="DAPI" SamplesPerPixel="1"/><Channel ID="Channel:0:1" Name="GFP" SamplesPerPixel="1"/></Pixels></Image></OME>"#
            )
        };
        let a = parse_ome_xml(&xml("XYZCT")).unwrap();
        assert_eq!((a.z_stride, a.channel_stride), (1, 5));
        assert_eq!(a.channel_names, ["DAPI", "GFP"]);
        assert_eq!(a.voxel_size, [Some(2.0), Some(0.5), Some(0.5)]);
        assert_eq!(a.unit.as_deref(), Some("micrometer"));
        let b = parse_ome_xml(&xml("XYCZT")).unwrap();
        assert_eq!((b.z_stride, b.channel_stride), (2, 1));
        assert!(parse_ome_xml(&xml("XYQZT")).is_err());
    }

    /// Found by fuzzing (tests/fuzz, target tiff_structured): `channels * frames` overflowed
    /// (a debug panic; wrapped to 0 in release, then a division by zero).
    #[test]
    fn imagej_sizes_beyond_u64_do_not_overflow() {
        let l = parse_imagej("ImageJ=1.54f\nimages=7\nchannels=4294967296\nframes=4294967296\n")
            .unwrap();
        assert_eq!(
            (l.channel_planes, l.depth, l.time_points),
            (1 << 32, 1, 1 << 32)
        );
    }

    /// The overflow fuzzing found in ImageJ sizes, in OME sizes: the page strides are their
    /// product.
    #[test]
    fn ome_sizes_beyond_u64_are_refused() {
        let xml = r#"<OME><Image><Pixels DimensionOrder="XYZCT" SizeZ="4294967296" SizeC="1" SizeT="4294967296"/></Image></OME>"#;
        assert_eq!(
            format!("{:#}", parse_ome_xml(xml).unwrap_err()),
            "OME-XML Pixels SizeZ 4294967296 x SizeC 1 x SizeT 4294967296 is more than 2^64 planes"
        );
    }
}
