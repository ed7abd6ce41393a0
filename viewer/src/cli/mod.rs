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
