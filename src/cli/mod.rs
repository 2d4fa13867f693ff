//! The command line: arguments, one module per command, the JSON report and the summary text.
//! A client of the library like any other; built only with the `cli` feature.

pub mod args;
pub mod commands;
pub mod driver;
pub mod flags;
pub mod lights;
pub mod relight;
pub mod report;
pub mod scene;
pub mod sweep;
pub mod text;
