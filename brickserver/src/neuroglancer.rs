//! The neuroglancer link of a dataset: a typed neuroglancer viewer state, put in the URL's
//! fragment (`https://neuroglancer-demo.appspot.com/#!{state as JSON, percent-encoded}`).
//!
//! What the state says, and why (checked against google/neuroglancer's source,
//! `src/datasource/zarr/frontend.ts`, `ome.ts` and `src/sliceview/image_layer_rendering.md`):
//! - **Source scheme.** `zarr://` leaves the Zarr version open: neuroglancer's `getMetadata`
//!   then fetches `.zarray`/`.zattrs` *and* `zarr.json` and takes whichever exists (and fails
//!   with "Both zarr v2 and v3 metadata found" if both do), while `zarr3://` reads only
//!   `zarr.json` and so fails on a 0.4 store ("No zarr metadata found"). We name the version
//!   we know: `zarr://` for Zarr v2 (OME-Zarr 0.4; every neuroglancer version reads it so),
//!   `zarr3://` for Zarr v3 (0.5), and `zarr://` when the store's metadata cannot be read.
//! - **Dimensions.** The global `x`, `y`, `z` dimensions are one level-0 voxel each, in SI
//!   base units (`[scale, "m"]`), as neuroglancer's OME reader derives them itself from the
//!   axes' units (`OME_UNITS`: SI-prefixed `meter`/`second`, `angstrom`, `inch`, ...) and the
//!   level-0 `scale`; an axis without a unit (or one neuroglancer does not know) is `""`.
//! - **Channels.** neuroglancer names an OME axis of type `channel` `c'`: a *local* dimension
//!   of the layer. Each channel becomes its own image layer at `localPosition` `[i + 0.5]`
//!   (the middle of channel `i`), blended additively, so every channel has its own display
//!   range and colour. A store whose channel axis is not typed `channel` gets one layer.
//! - **Display range.** The `omero` window's `start`/`end` (swapped when `inverted`, clamped
//!   to `min`/`max` as neuroglancer's own OME reader does) is the `range` of an `invlerp`
//!   shader control named `normalized`, and `min`/`max` its `window`; the `omero` colour
//!   (`RRGGBB`) a `vec3` colour control named `color`. Without a window neuroglancer's
//!   default applies (the data type's whole range). Inactive channels are hidden layers.

use std::collections::BTreeMap;

use residency_schemas::ome::{Axis, ImageAttributes, OmeroChannel, PyramidLayout, ZarrFormat};
use serde::{Deserialize, Serialize};

/// The neuroglancer app the links open.
pub const APP_URL: &str = "https://neuroglancer-demo.appspot.com/";

/// The shader of every layer: the channel's value through the `normalized` range, in its
/// colour.
pub const SHADER: &str = "#uicontrol invlerp normalized\n\
                          #uicontrol vec3 color color(default=\"white\")\n\
                          void main() {\n  emitRGB(color * normalized());\n}\n";

/// One dimension of a coordinate space: the size of one unit step, in `unit` (an SI base
/// unit such as `"m"` or `"s"`, or `""`); written as the JSON pair `[scale, unit]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Dimension(pub f64, pub String);

/// The global coordinate space: the three spatial axes, in this order.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SpatialDimensions {
    /// The `x` axis.
    pub x: Dimension,
    /// The `y` axis.
    pub y: Dimension,
    /// The `z` axis.
    pub z: Dimension,
}

/// A neuroglancer viewer state, as much of it as a link sets.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct State {
    /// The global coordinate space (`None`: neuroglancer's, from the data).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dimensions: Option<SpatialDimensions>,
    /// The layers, drawn in order.
    pub layers: Vec<ImageLayer>,
}

/// The kind of a layer.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum LayerKind {
    /// An image (volume) layer.
    #[serde(rename = "image")]
    Image,
}

/// How a layer is composited over those before it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Blend {
    /// Over, by alpha.
    #[serde(rename = "default")]
    Default,
    /// Added: channels mix into one image.
    #[serde(rename = "additive")]
    Additive,
}

/// An image layer.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct ImageLayer {
    /// Always [`LayerKind::Image`].
    #[serde(rename = "type")]
    pub kind: LayerKind,
    /// Name, unique in the state.
    pub name: String,
    /// Data source URL: `zarr://URL` or `zarr3://URL`.
    pub source: String,
    /// The layer's local dimensions (`c'`: the channel axis), if any.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub local_dimensions: BTreeMap<String, Dimension>,
    /// The position along the local dimensions (the channel shown).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub local_position: Vec<f64>,
    /// The shader, [`SHADER`].
    pub shader: String,
    /// The values of the shader's controls.
    pub shader_controls: ShaderControls,
    /// Opacity, 0 to 1.
    pub opacity: f64,
    /// Compositing.
    pub blend: Blend,
    /// Whether the layer is shown.
    pub visible: bool,
}

/// The values of [`SHADER`]'s controls.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ShaderControls {
    /// The display range; `None`: neuroglancer's default (the data type's range).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub normalized: Option<Invlerp>,
    /// The colour, `#rrggbb`.
    pub color: String,
}

/// The value of an `invlerp` shader control.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Invlerp {
    /// The values mapped to 0 and 1.
    pub range: [f64; 2],
    /// The interval the control's histogram shows.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub window: Option<[f64; 2]>,
}

/// The size of one OME unit in neuroglancer's SI base unit (`m` or `s`), for the unit names
/// neuroglancer's OME reader accepts; `None` for any other.
pub(crate) fn si_unit(ome_unit: &str) -> Option<(f64, &'static str)> {
    // The SI prefixes, as neuroglancer's `allSiPrefixes` long names.
    const PREFIXES: [(&str, f64); 25] = [
        ("quetta", 1e30),
        ("ronna", 1e27),
        ("yotta", 1e24),
        ("zetta", 1e21),
        ("exa", 1e18),
        ("peta", 1e15),
        ("tera", 1e12),
        ("giga", 1e9),
        ("mega", 1e6),
        ("kilo", 1e3),
        ("hecto", 1e2),
        ("deca", 1e1),
        ("", 1.0),
        ("deci", 1e-1),
        ("centi", 1e-2),
        ("milli", 1e-3),
        ("micro", 1e-6),
        ("nano", 1e-9),
        ("pico", 1e-12),
        ("femto", 1e-15),
        ("atto", 1e-18),
        ("zepto", 1e-21),
        ("yocto", 1e-24),
        ("ronto", 1e-27),
        ("quecto", 1e-30),
    ];
    let other = match ome_unit {
        "angstrom" => Some((1e-10, "m")),
        "foot" => Some((0.3048, "m")),
        "inch" => Some((0.0254, "m")),
        "mile" => Some((1609.34, "m")),
        "parsec" => Some((3.085_677_581_491_367e16, "m")),
        "yard" => Some((0.9144, "m")),
        "minute" => Some((60.0, "s")),
        "hour" => Some((3600.0, "s")),
        "day" => Some((86400.0, "s")),
        _ => None,
    };
    other.or_else(|| {
        [("meter", "m"), ("second", "s")]
            .into_iter()
            .find_map(|(base, si)| {
                let prefix = ome_unit.strip_suffix(base)?;
                let (_, factor) = PREFIXES.iter().find(|(p, _)| *p == prefix)?;
                Some((*factor, si))
            })
    })
}

/// The neuroglancer dimension of one level-0 voxel along `axis`, `scale` wide.
fn dimension(axis: Option<&Axis>, scale: f64) -> Dimension {
    match axis.and_then(|a| a.unit.as_deref()).and_then(si_unit) {
        Some((factor, unit)) => Dimension(scale * factor, unit.to_string()),
        None => Dimension(scale, String::new()),
    }
}

/// The data source URL of a store at `store_url`, in Zarr format `format` (`None`: unknown).
pub fn source(store_url: &str, format: Option<ZarrFormat>) -> String {
    let scheme = match format {
        Some(ZarrFormat::V3) => "zarr3",
        Some(ZarrFormat::V2) | None => "zarr",
    };
    format!("{scheme}://{store_url}")
}

/// The colour of an `omero` channel (`RRGGBB`, or `#RRGGBB`) as `#rrggbb`; white otherwise.
fn colour(channel: Option<&OmeroChannel>) -> String {
    channel
        .and_then(|c| c.color.as_deref())
        .map(|c| c.strip_prefix('#').unwrap_or(c))
        .filter(|c| c.len() == 6 && c.bytes().all(|b| b.is_ascii_hexdigit()))
        .map_or_else(
            || "#ffffff".to_string(),
            |c| format!("#{}", c.to_lowercase()),
        )
}

/// The display range of an `omero` channel: its window's `start`/`end`, swapped when
/// inverted and clamped to `min`/`max`, with `min`/`max` as the histogram window.
fn display_range(channel: Option<&OmeroChannel>) -> Option<Invlerp> {
    let channel = channel?;
    let w = channel.window.as_ref()?;
    let finite = |v: Option<f64>| v.filter(|v| v.is_finite());
    let window = match (finite(w.min), finite(w.max)) {
        (Some(lo), Some(hi)) if lo < hi => Some([lo, hi]),
        _ => None,
    };
    let (mut start, mut end) = (finite(w.start)?, finite(w.end)?);
    if let Some([lo, hi]) = window {
        start = start.clamp(lo, hi);
        end = end.clamp(lo, hi);
    }
    if start == end {
        return None;
    }
    let range = if channel.inverted == Some(true) {
        [end, start]
    } else {
        [start, end]
    };
    Some(Invlerp { range, window })
}

/// The state that opens the store at `store_url` (named `name`), of Zarr format `format`, with
/// OME metadata `attributes` (laid out as `layout`) and `channels` channels.
pub fn state(
    name: &str,
    store_url: &str,
    format: ZarrFormat,
    attributes: &ImageAttributes,
    layout: &PyramidLayout,
    channels: u64,
) -> State {
    let axes = &attributes.image().axes;
    let n = axes.len();
    let scale = layout.level_scales[0];
    let spatial = |a: usize| dimension(axes.get(n - 3 + a), scale[a]);
    let dimensions = SpatialDimensions {
        z: spatial(0),
        y: spatial(1),
        x: spatial(2),
    };
    let source = source(store_url, Some(format));
    // A channel axis of type `channel` is neuroglancer's local dimension NAME'.
    let local = layout
        .channel_axis
        .map(|c| &axes[c])
        .filter(|a| a.kind.as_deref() == Some("channel"))
        .map(|a| format!("{}'", a.name));
    let omero = attributes.omero.as_ref().map(|o| o.channels.as_slice());
    let omero_channel = |i: usize| omero.and_then(|o| o.get(i));
    let shown = if local.is_some() { channels.max(1) } else { 1 };
    let labels: Vec<String> = (0..shown as usize)
        .map(|i| {
            omero_channel(i)
                .and_then(|c| c.label.clone())
                .filter(|l| !l.is_empty())
                .unwrap_or_else(|| format!("c{i}"))
        })
        .collect();
    let unique = labels
        .iter()
        .enumerate()
        .all(|(i, l)| !labels[..i].contains(l));
    let layers = labels
        .iter()
        .enumerate()
        .map(|(i, label)| {
            let c = omero_channel(i);
            let name = match (&local, unique) {
                (None, _) => name.to_string(),
                (Some(_), true) => format!("{name} {label}"),
                (Some(_), false) => format!("{name} c{i} {label}"),
            };
            layer(name, source.clone(), local.as_deref().map(|l| (l, i)), c)
        })
        .collect();
    State {
        dimensions: Some(dimensions),
        layers,
    }
}

/// The state of a store whose metadata could not be read: one layer with neuroglancer's
/// defaults, the Zarr version left to neuroglancer.
pub(crate) fn fallback_state(name: &str, store_url: &str) -> State {
    State {
        dimensions: None,
        layers: vec![layer(name.to_string(), source(store_url, None), None, None)],
    }
}

/// One image layer of channel `channel` (its `omero` entry: colour, window, active), on the
/// local dimension `local` at index `i` when the store has a channel axis.
fn layer(
    name: String,
    source: String,
    local: Option<(&str, usize)>,
    channel: Option<&OmeroChannel>,
) -> ImageLayer {
    ImageLayer {
        kind: LayerKind::Image,
        name,
        source,
        local_dimensions: local
            .iter()
            .map(|(l, _)| ((*l).to_string(), Dimension(1.0, String::new())))
            .collect(),
        local_position: local.iter().map(|&(_, i)| i as f64 + 0.5).collect(),
        shader: SHADER.to_string(),
        shader_controls: ShaderControls {
            normalized: display_range(channel),
            color: colour(channel),
        },
        opacity: 1.0,
        blend: Blend::Additive,
        visible: channel.and_then(|c| c.active).unwrap_or(true),
    }
}

/// The link opening `state` in [`APP_URL`].
pub fn link(state: &State) -> String {
    let json = serde_json::to_string(state).expect("a state serializes");
    let fragment = percent_encoding::utf8_percent_encode(&json, percent_encoding::NON_ALPHANUMERIC);
    format!("{APP_URL}#!{fragment}")
}

/// Why a link could not be parsed back into a [`State`].
#[derive(Debug, thiserror::Error)]
pub enum LinkError {
    /// The link does not start with [`APP_URL`] and `#!`.
    #[error("not a neuroglancer link: {0}")]
    NotALink(String),
    /// The fragment's percent-decoded bytes are not UTF-8.
    #[error(transparent)]
    NotUtf8(#[from] std::str::Utf8Error),
    /// The fragment is not a [`State`].
    #[error("{source}: {json}")]
    NotAState {
        /// The decoded fragment.
        json: String,
        /// What serde found.
        source: serde_json::Error,
    },
}

/// The state in a link made by [`link`], parsed back (for tests and tools).
///
/// # Errors
/// [`LinkError`] when `link` is not an [`APP_URL`] link or its fragment is not a [`State`].
pub fn parse_link(link: &str) -> Result<State, LinkError> {
    let fragment = link
        .strip_prefix(APP_URL)
        .and_then(|rest| rest.strip_prefix("#!"))
        .ok_or_else(|| LinkError::NotALink(link.to_string()))?;
    let json = percent_encoding::percent_decode_str(fragment).decode_utf8()?;
    serde_json::from_str(&json).map_err(|source| LinkError::NotAState {
        json: json.to_string(),
        source,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ome_units_become_si_units_as_neuroglancer_reads_them() {
        assert_eq!(si_unit("micrometer"), Some((1e-6, "m")));
        assert_eq!(si_unit("nanometer"), Some((1e-9, "m")));
        assert_eq!(si_unit("meter"), Some((1.0, "m")));
        assert_eq!(si_unit("millisecond"), Some((1e-3, "s")));
        assert_eq!(si_unit("angstrom"), Some((1e-10, "m")));
        assert_eq!(si_unit("hour"), Some((3600.0, "s")));
        for unknown in ["micron", "um", "", "pixel", "kilometers"] {
            assert_eq!(si_unit(unknown), None, "{unknown}");
        }
    }

    #[test]
    fn colours_and_ranges_follow_omero() {
        use residency_schemas::ome::OmeroWindow;
        let mut c = OmeroChannel {
            label: None,
            color: Some("00FF7f".into()),
            window: Some(OmeroWindow {
                min: Some(0.0),
                max: Some(65535.0),
                start: Some(100.0),
                end: Some(70000.0),
            }),
            active: None,
            coefficient: None,
            family: None,
            inverted: None,
        };
        assert_eq!(colour(Some(&c)), "#00ff7f");
        assert_eq!(
            display_range(Some(&c)),
            Some(Invlerp {
                range: [100.0, 65535.0],
                window: Some([0.0, 65535.0])
            })
        );
        c.inverted = Some(true);
        assert_eq!(display_range(Some(&c)).unwrap().range, [65535.0, 100.0]);
        c.color = Some("red".into());
        assert_eq!(colour(Some(&c)), "#ffffff");
        c.window.as_mut().unwrap().end = Some(100.0);
        assert_eq!(display_range(Some(&c)), None);
        assert_eq!(display_range(None), None);
    }

    #[test]
    fn sources_name_the_zarr_version() {
        assert_eq!(
            source("http://h/a/", Some(ZarrFormat::V2)),
            "zarr://http://h/a/"
        );
        assert_eq!(
            source("http://h/a/", Some(ZarrFormat::V3)),
            "zarr3://http://h/a/"
        );
        assert_eq!(source("http://h/a/", None), "zarr://http://h/a/");
    }
}
