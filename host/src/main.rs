//! `imucal` command-line tool: a thin layer over the `imucal` library.
#![forbid(unsafe_code)]

/// `eprintln!` that never ends the command: a message to a standard error that was closed (the
/// reader of `2>&1 | head` gone) or is full is lost, and the work and its exit status go on.
macro_rules! say {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stderr(), $($arg)*);
    }};
}

/// [`say!`] without the line end (a prompt, or text that ends its own lines).
macro_rules! say_part {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let _ = write!(std::io::stderr(), $($arg)*);
    }};
}

mod cli;

use std::any::Any;
use std::io::ErrorKind;
use std::process::ExitCode;

use clap::{CommandFactory, FromArgMatches};

use cli::args::{Cli, Command};

/// `command` and its subcommands with every option value allowed to be a negative number (and
/// real-number or listed-choice values to start with a hyphen): `--min-hold -1` then reaches the
/// option's own check ("must be ≥ 0"), instead of clap reading `-1` as a flag and suggesting
/// `-- -1`, which passes it as a file name.
fn negative_values_allowed(command: clap::Command) -> clap::Command {
    let real = std::any::TypeId::of::<f64>();
    command
        .mut_args(|arg| {
            if !arg.get_action().takes_values() || arg.is_positional() {
                return arg;
            }
            // A real number (`-.5`, `-inf`) or a choice from a list (`--sensor -x`) reaches its
            // own check, which names the option and what it takes; clap would only suggest
            // `-- -x`, which passes the value as a file name. Free text keeps clap's rule, so
            // `--out --json` is not taken for a file named `--json`.
            if arg.get_value_parser().type_id() == real || !arg.get_possible_values().is_empty() {
                arg.allow_hyphen_values(true)
            } else {
                arg.allow_negative_numbers(true)
            }
        })
        .mut_subcommands(negative_values_allowed)
}

fn main() -> ExitCode {
    let matches = negative_values_allowed(Cli::command()).get_matches();
    let cli = Cli::from_arg_matches(&matches).unwrap_or_else(|e| e.exit());
    // `print!` panics when standard output fails: a reader that closed the pipe
    // (`imucal ports | head -0`) or a full disk. Such a failure ends the command as described in
    // `output_failure`, never with a panic message; any other panic keeps the default report.
    let default_hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        if output_error(info.payload()).is_none() {
            default_hook(info);
        }
    }));
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| run(cli))) {
        Ok(code) => code,
        Err(payload) => match output_error(payload.as_ref()) {
            Some(error) => output_failure(&error),
            None => std::panic::resume_unwind(payload),
        },
    }
}

/// `imucal calibrate` in the session its options choose, once they agree with each other.
fn calibrate(args: &cli::args::CalibrateArgs) -> anyhow::Result<()> {
    args.check_combination()?;
    cli::history::check_before_writing(&args.history)?;
    if args.talks_motioncal() {
        // A board running the MotionCal sketch has a session of its own.
        cli::calibrate_motioncal::run(args)
    } else if args.is_batch() {
        cli::calibrate_batch::run(args)
    } else {
        cli::calibrate::run(args)
    }
}

fn run(cli: Cli) -> ExitCode {
    let result = match cli.command {
        Command::Fit(args) => cli::fit::run(&args),
        Command::Calibrate(args) => calibrate(&args),
        Command::Still(args) => cli::still::run(&args),
        Command::Analyze(args) => cli::analyze::run(&args),
        Command::Device(command) => cli::device::run(&command),
        Command::Report(args) => cli::report::run(&args),
        Command::Export(args) => cli::export::run(&args),
        Command::History(args) => cli::history::run(&args),
        Command::Fleet(args) => cli::fleet::run(&args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            if let Some(io) = error
                .downcast_ref::<std::io::Error>()
                .filter(|e| e.kind() == ErrorKind::BrokenPipe)
            {
                return output_failure(io);
            }
            say!("imucal: {error:#}");
            if error.chain().any(|cause| cause.is::<cli::UsageError>()) {
                ExitCode::from(2)
            } else {
                ExitCode::FAILURE
            }
        }
    }
}

/// A reader that went away wanted no more output: exit quietly with success, as `cat` and
/// `grep` do under `head`. Any other failure to write (a full disk) is an error with a sentence.
fn output_failure(error: &std::io::Error) -> ExitCode {
    if error.kind() == ErrorKind::BrokenPipe {
        return ExitCode::SUCCESS;
    }
    // Standard error may be the same full disk; nothing more can be done then.
    let _ = std::io::Write::write_all(
        &mut std::io::stderr(),
        format!(
            "imucal: cannot write the output ({error}); free space where standard output goes, or redirect it elsewhere\n"
        )
        .as_bytes(),
    );
    ExitCode::FAILURE
}

/// The I/O error behind a `print!` panic (`"failed printing to stdout: … (os error N)"`),
/// rebuilt from the OS error number; `None` for any other panic.
fn output_error(payload: &(dyn Any + Send)) -> Option<std::io::Error> {
    let message = payload
        .downcast_ref::<String>()
        .map(String::as_str)
        .or_else(|| payload.downcast_ref::<&str>().copied())?;
    let detail = message.strip_prefix("failed printing to stdout: ")?;
    let code = detail
        .rsplit_once("(os error ")?
        .1
        .strip_suffix(')')?
        .parse::<i32>()
        .ok()?;
    Some(std::io::Error::from_raw_os_error(code))
}
