//! `imucal-hil-sim`: the simulated imucal board on the command line.
//!
//! `record` writes a simulated recording (CSV) and its truth (JSON) without any serial link.
//! `serve` (the default) runs the board behind a pseudo-terminal and prints its path; serve's
//! options given without a command (`imucal-hil-sim --seed 3`) run `serve` with them.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};

use imucal_hil_sim::effects::EffectRequest;
use imucal_hil_sim::poser::ScheduleKind;
use imucal_hil_sim::recording::{simulate_recording, write_csv_file, write_truth_file, SimConfig};
use imucal_hil_sim::serve::BoardProtocol;
use imucal_hil_sim::world::TemperatureProfile;

/// A simulated IMU board (LSM9DS1 or BMI270 + BMM150; imucal's firmware or the MotionCal sketch).
#[derive(Debug, Parser)]
#[command(
    name = "imucal-hil-sim",
    version,
    args_conflicts_with_subcommands = true
)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
    /// Options of `serve`, used when no command is given.
    #[command(flatten)]
    serve: imucal_hil_sim::serve::ServeArgs,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Run the board behind a pseudo-terminal (the default) and print the port path on stdout.
    #[command(after_help = "\
Example:
  imucal-hil-sim serve --seed 7 --effect bias_temperature --speed 10
  # prints e.g. /dev/pts/7; then, in another terminal: imucal info --port /dev/pts/7

Stops at end of stdin (Ctrl-D), after --seconds, or on Ctrl-C. The simulated person holds each
of twelve positions until the firmware has captured it (or --max-hold passes), tumbles for the
magnetometer, then rests.")]
    Serve(imucal_hil_sim::serve::ServeArgs),
    /// Feed an emulated board's sensor UART (a unix socket served by QEMU) with timed holds.
    #[command(after_help = "\
Example:
  imucal-hil-sim feed --socket /tmp/uart1.sock --seed 7 --speed 2 --truth truth.json

The person waits --lead-in feed seconds in the first position, holds each of the twelve
positions for --hold feed seconds (they cannot see the board, so holds are timed), tumbles for
the magnetometer, then rests until the emulator closes the socket or --seconds pass.")]
    Feed(imucal_hil_sim::feed::FeedArgs),
    /// Simulate a person following a calibration schedule and write the uncalibrated recording.
    #[command(after_help = "\
Example:
  imucal-hil-sim record --seed 7 --schedule sweep \\
      --effect bias_temperature --effect gyro.g_sensitivity=2 \\
      -o rec.csv --truth truth.json

Effects (`[accel.|gyro.|mag.]name[=size]`, size 1 = a typical consumer part, default all sensors):
  bias_temperature, scale_temperature, bias_drift, scale_nonlinearity, g_sensitivity (gyro only),
  bias_step, thermal_hysteresis, bias_random_walk

CSV columns: t_s,ax,ay,az,gx,gy,gz,mx,my,mz,temp_c,pose (s, m/s², rad/s, µT, °C); pose is the
hold label during static holds and empty while moving.")]
    Record {
        /// Seed of every random draw; the same seed gives the same bytes.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Schedule the simulated person follows: twelve, tumble or sweep.
        #[arg(long, default_value = "twelve")]
        schedule: ScheduleKind,
        /// Switch an effect on (repeatable): `[sensor.]name[=size]`.
        #[arg(long = "effect")]
        effects: Vec<EffectRequest>,
        /// Output CSV file.
        #[arg(short = 'o', long = "output")]
        output: PathBuf,
        /// Also write every true parameter as JSON here.
        #[arg(long)]
        truth: Option<PathBuf>,
        /// Sample rate, Hz.
        #[arg(long, default_value_t = 100.0)]
        rate: f64,
        /// Seconds per static hold.
        #[arg(long, default_value_t = 4.0)]
        hold_s: f64,
        /// Hold perfectly still (no hand tremor).
        #[arg(long)]
        no_tremor: bool,
        /// Constant die temperature in °C, replacing the schedule's profile.
        #[arg(long)]
        temp_c: Option<f64>,
    },
}

fn run(cli: Cli) -> Result<(), Box<dyn std::error::Error>> {
    let command = cli.command.unwrap_or(Command::Serve(cli.serve));
    match command {
        Command::Serve(args) if args.protocol == BoardProtocol::Motioncal => {
            Ok(imucal_hil_sim::motioncal_serve::run_command(&args)?)
        }
        Command::Serve(args) => Ok(imucal_hil_sim::serve::run_command(&args)?),
        Command::Feed(args) => Ok(imucal_hil_sim::feed::run_command(&args)?),
        Command::Record {
            seed,
            schedule,
            effects,
            output,
            truth,
            rate,
            hold_s,
            no_tremor,
            temp_c,
        } => {
            let mut config = SimConfig::new(seed, schedule);
            config.effects = effects;
            config.sample_rate_hz = rate;
            config.poser.hold_s = hold_s;
            config.poser.tremor = !no_tremor;
            config.temperature = temp_c.map(|temp_c| TemperatureProfile::Constant { temp_c });
            let recording = simulate_recording(&config)?;
            write_csv_file(&recording, &output)?;
            if let Some(path) = truth {
                write_truth_file(&recording.truth, &path)?;
            }
            eprintln!(
                "wrote {} samples ({:.1} s, {} holds) to {}",
                recording.samples.len(),
                recording.truth.duration_s,
                recording
                    .samples
                    .iter()
                    .filter_map(|s| s.pose)
                    .max()
                    .map_or(0, |m| m + 1),
                output.display()
            );
            Ok(())
        }
    }
}

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("error: {error}");
            ExitCode::FAILURE
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    #[test]
    fn command_line_definition_is_consistent() {
        Cli::command().debug_assert();
    }

    #[test]
    fn serve_options_without_a_command_run_serve_with_them() {
        let cli = Cli::try_parse_from(["imucal-hil-sim", "--seed", "3", "--speed", "10"])
            .expect("serve options parse without a command");
        assert!(cli.command.is_none());
        assert_eq!(cli.serve.seed, 3);
        assert_eq!(cli.serve.speed, 10.0);
    }

    #[test]
    fn bare_invocation_serves_with_the_defaults() {
        let cli = Cli::try_parse_from(["imucal-hil-sim"]).expect("no arguments parse");
        assert!(cli.command.is_none());
        assert_eq!(cli.serve, imucal_hil_sim::serve::ServeArgs::default());
    }

    #[test]
    fn explicit_commands_still_parse_and_do_not_mix_with_top_level_options() {
        let cli = Cli::try_parse_from(["imucal-hil-sim", "serve", "--seed", "5"])
            .expect("serve command parses");
        assert!(matches!(cli.command, Some(Command::Serve(ref a)) if a.seed == 5));
        let cli = Cli::try_parse_from(["imucal-hil-sim", "record", "--seed", "4", "-o", "r.csv"])
            .expect("record command parses");
        assert!(matches!(cli.command, Some(Command::Record { seed: 4, .. })));
        // Options before a command would be silently ignored; they are refused instead.
        assert!(
            Cli::try_parse_from(["imucal-hil-sim", "--seed", "3", "record", "-o", "r.csv"])
                .is_err()
        );
    }
}
