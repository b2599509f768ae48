//! `imucal` command-line tool: a thin layer over the `imucal` library.
#![forbid(unsafe_code)]

mod cli;

use clap::Parser;

use cli::args::{Cli, Command};

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Fit(args) => cli::fit::run(&args),
        Command::Calibrate(args) => cli::calibrate::run(&args),
        Command::Still(args) => cli::still::run(&args),
        Command::Analyze(args) => cli::analyze::run(&args),
        Command::Device(command) => cli::device::run(&command),
        Command::Report(args) => cli::report::run(&args),
        Command::Export(args) => cli::export::run(&args),
        Command::History(args) => cli::history::run(&args),
        Command::Fleet(args) => cli::fleet::run(&args),
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("imucal: {error:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
