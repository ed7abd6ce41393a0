//! The inputs of a conversion, opened and checked against each other ([`Inputs`]).

use super::error::ConvertError;
use super::options::ConvertOptions;
use crate::sample_format::SampleType;
use crate::source::{SourceInfo, VolumeSource, open_input};

/// The inputs, opened and checked against each other.
pub(crate) struct Inputs {
    pub(crate) sources: Vec<Box<dyn VolumeSource>>,
    pub(crate) shape: [u64; 3],
    pub(crate) format: SampleType,
    pub(crate) voxel_size: Option<[f64; 3]>,
    pub(crate) unit: Option<String>,
    pub(crate) labels: Vec<String>,
}

pub(crate) fn open_inputs(options: &ConvertOptions) -> Result<Inputs, ConvertError> {
    if options.inputs.is_empty() {
        return Err(ConvertError::NoInput);
    }
    let sources: Vec<Box<dyn VolumeSource>> = options
        .inputs
        .iter()
        .map(|i| open_input(i, &options.raw))
        .collect::<Result<_, _>>()?;
    let first: &SourceInfo = sources[0].info();
    let mut format = first.format;
    for s in &sources[1..] {
        let info = s.info();
        if info.shape != first.shape {
            return Err(ConvertError::ShapeMismatch {
                first: first.path.clone(),
                first_shape: first.shape,
                path: info.path.clone(),
                shape: info.shape,
            });
        }
        format = SampleType::promote(format, info.format).ok_or_else(|| {
            ConvertError::IncompatibleSamples {
                path: info.path.clone(),
                format: info.format,
                others: format,
                first: first.path.clone(),
            }
        })?;
    }
    if first.shape.contains(&0) {
        return Err(ConvertError::EmptyVolume {
            path: first.path.clone(),
            shape: first.shape,
        });
    }
    let channels: usize = sources.iter().map(|s| s.info().channels).sum();
    let mut labels: Vec<String> = Vec::new();
    for s in &sources {
        let info = s.info();
        let stem = info
            .path
            .file_name()
            .map(|n| {
                n.to_string_lossy()
                    .split('.')
                    .next()
                    .unwrap_or("")
                    .to_string()
            })
            .unwrap_or_default();
        for c in 0..info.channels {
            labels.push(info.channel_names.get(c).cloned().unwrap_or_else(|| {
                if info.channels == 1 {
                    stem.clone()
                } else {
                    format!("{stem} {c}")
                }
            }));
        }
    }
    for (i, l) in options.channel_names.iter().enumerate().take(channels) {
        labels[i].clone_from(l);
    }
    let voxel_size = options
        .voxel_size
        .or_else(|| sources.iter().find_map(|s| s.info().voxel_size));
    let unit = options
        .unit
        .clone()
        .or_else(|| sources.iter().find_map(|s| s.info().unit.clone()));
    Ok(Inputs {
        shape: first.shape,
        format,
        voxel_size,
        unit,
        labels,
        sources,
    })
}
