//! The `viewer` subcommands, one module each.

pub mod bench;
pub mod compare;
pub mod reference;
pub mod render;
pub mod renderer_args;
pub mod scene_args;
pub mod serve;
pub mod vdi;
pub mod view;

/// Writes a command's report to stdout. A reader that has gone (a closed pipe: `viewer compare
/// A B | head -1`) is no error: the work is done, and the rest of the report goes nowhere.
///
/// # Errors
/// When stdout cannot be written for another reason.
pub fn report(text: std::fmt::Arguments) -> std::io::Result<()> {
    use std::io::Write;
    let mut stdout = std::io::stdout().lock();
    match stdout.write_fmt(text).and_then(|()| stdout.flush()) {
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        other => other,
    }
}

/// Parses a flag whose values are the variant names of one of the library's named enums
/// (`--method`, `--filter`, `--mode`, `--experiment`): clap lists them in the help and in the
/// error for any other value.
pub fn names_parser<E>() -> impl clap::builder::TypedValueParser<Value = E>
where
    E: strum::VariantNames + std::str::FromStr + Clone + Send + Sync + 'static,
    E::Err: std::fmt::Debug,
{
    use clap::builder::TypedValueParser;
    clap::builder::PossibleValuesParser::new(E::VARIANTS)
        .map(|s| s.parse::<E>().expect("one of the possible values"))
}

/// Parses a sampling along the ray `D_R` (`--ray-sampling`, `--vdi-ray-sampling`): a number in
/// [`MIN_RAY_SAMPLING`, 1].
///
/// # Errors
/// A message naming the value and the range.
///
/// [`MIN_RAY_SAMPLING`]: residency_viewer::gpu::vdi_render::MIN_RAY_SAMPLING
pub fn ray_sampling(text: &str) -> Result<f64, String> {
    use residency_viewer::gpu::vdi_render::MIN_RAY_SAMPLING;
    match text.trim().parse::<f64>() {
        Ok(d) if (MIN_RAY_SAMPLING..=1.0).contains(&d) => Ok(d),
        _ => Err(format!(
            "'{text}' is not a sampling along the ray: a number from {MIN_RAY_SAMPLING} to 1 \
             (the share of the lists a ray crosses that it reads)"
        )),
    }
}
