//! `antiradiance`: the command line. It only parses arguments and hands them to
//! [`cli`]; every failure ends as one line `error: ...` on stderr.
//!
//! Exit codes: 0 success, 1 error (bad scene, bad parameter, failed write), 2 bad command line.

use std::process::ExitCode;

mod cli;

use clap::{Parser, Subcommand};
use cli::driver;

/// Diffuse global illumination on triangle meshes with the antiradiance method.
#[derive(Parser, Debug)]
#[command(name = "antiradiance", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Solve a scene with the antiradiance method (hierarchical or dense solver).
    Solve(driver::SolveArgs),
    /// Estimate the ground truth of a scene with the path tracer.
    Reference(driver::ReferenceArgs),
    /// Run the dense and hierarchical solvers on one scene and compare them.
    Compare(driver::CompareArgs),
    /// Animate the lights of a scene: build links once, relight every frame, write PNG frames.
    Relight(cli::relight::RelightArgs),
    /// Measure time and error against the path tracer over a grid of solver knobs.
    Sweep(cli::sweep::SweepArgs),
    /// Write a generated scene (OBJ + MTL): the Cornell box, a mesh in a closed room, a mesh
    /// under an area light, a badly triangulated variant of a mesh, a CAD-like classroom or
    /// office.
    Scene(cli::scene::StageArgs),
}

fn main() -> ExitCode {
    install_panic_hook();
    let parsed = match Cli::try_parse() {
        Ok(parsed) => parsed,
        Err(e) => return usage_error(e),
    };
    let result = match &parsed.command {
        Command::Solve(args) => driver::solve(args),
        Command::Reference(args) => driver::reference(args),
        Command::Compare(args) => driver::compare(args),
        Command::Relight(args) => cli::relight::relight(args),
        Command::Sweep(args) => cli::sweep::sweep(args),
        Command::Scene(args) => cli::scene::stage(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!(
                "error: {}",
                driver::one_line(&cli::flags::flagged(&e.to_string()))
            );
            ExitCode::from(1)
        }
    }
}

/// `--help` and `--version` print as usual; any other command-line error becomes one line.
fn usage_error(e: clap::Error) -> ExitCode {
    use clap::error::ErrorKind;
    match e.kind() {
        ErrorKind::DisplayHelp
        | ErrorKind::DisplayVersion
        | ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand => {
            let _ = e.print();
            return if e.kind() == ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand {
                ExitCode::from(2)
            } else {
                ExitCode::SUCCESS
            };
        }
        _ => {}
    }
    // clap's message: "error: <what>", sometimes continued on indented lines, then "Usage: ..."
    // and "For more information, try '--help'.".
    let rendered = e.render().to_string();
    let mut message = String::new();
    for line in rendered
        .lines()
        .map(str::trim)
        .take_while(|l| !l.starts_with("Usage:") && !l.starts_with("For more information"))
        .filter(|l| !l.is_empty())
    {
        if !message.is_empty() {
            message.push_str(if line.starts_with("tip:") { "; " } else { " " });
        }
        message.push_str(line);
    }
    let message = message.strip_prefix("error:").unwrap_or(&message).trim();
    eprintln!("error: {message} (see --help)");
    ExitCode::from(2)
}

/// A bug must still end as one line on stderr (set RUST_BACKTRACE for the full report).
fn install_panic_hook() {
    if std::env::var_os("RUST_BACKTRACE").is_some() {
        return;
    }
    std::panic::set_hook(Box::new(|info| {
        let message = info
            .payload()
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| info.payload().downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "unknown panic".to_string());
        let location = info
            .location()
            .map(|l| format!(" at {}:{}", l.file(), l.line()))
            .unwrap_or_default();
        eprintln!(
            "error: internal error (a bug, please report it): {}{location}",
            driver::one_line(&message)
        );
    }));
}
