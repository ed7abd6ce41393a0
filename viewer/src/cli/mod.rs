//! The `viewer` subcommands, one module each.

pub mod compare;
pub mod scene_args;
pub mod reference;
pub mod render;
