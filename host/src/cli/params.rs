//! `imucal params get` and `imucal params reset`: the board's active parameter set read into the
//! versioned parameter file that `calibrate` and `fit --params-out` write (bound to the board, so
//! `imucal flash` takes it back on the same board and refuses it on another), and the identity
//! set written after confirmation, then verified by reading it back as `flash` does.

use std::path::PathBuf;

use anyhow::Context;
use clap::{Args, Subcommand};
use imucal::device::params_json::Provenance;
use imucal::device::ParamsFile;
use imucal_protocol::CalibrationSet;

use super::board::{connect, describe_params, PortArgs};
use super::write_policy::{check_outputs, Confirmation, Output};

/// `imucal params …`.
#[derive(Debug, Subcommand)]
pub enum ParamsCommand {
    /// Read the board's active parameter set into a parameter file (for `imucal flash`,
    /// `imucal export`, or a backup before recalibrating).
    #[command(
        after_help = "Examples:\n  imucal params get --port /dev/ttyACM0 -o board42-backup.json\n  \
        imucal flash board42-backup.json --port /dev/ttyACM0      (restores it)"
    )]
    Get(GetArgs),
    /// Reset the board's parameters to identity (uncalibrated), after confirmation.
    #[command(
        after_help = "Examples:\n  imucal params reset --port /dev/ttyACM0\n  \
        imucal params reset --port /dev/ttyACM0 --yes      (scripts: no question)"
    )]
    Reset(ResetArgs),
}

/// Arguments of `imucal params get`.
#[derive(Debug, Args)]
pub struct GetArgs {
    /// Which port to use.
    #[command(flatten)]
    pub port: PortArgs,
    /// The parameter file to write.
    #[arg(long, short = 'o')]
    pub output: PathBuf,
    /// Replace the output file when it exists.
    #[arg(long)]
    pub force: bool,
}

/// Arguments of `imucal params reset`.
#[derive(Debug, Args)]
pub struct ResetArgs {
    /// Which port to use.
    #[command(flatten)]
    pub port: PortArgs,
    /// Reset without asking (needed when standard input is not a terminal).
    #[arg(long, short = 'y')]
    pub yes: bool,
    /// Where to record the reset.
    #[command(flatten)]
    pub history: super::history::RecordArgs,
}

/// Runs a `params` command.
pub fn run(command: &ParamsCommand) -> anyhow::Result<()> {
    match command {
        ParamsCommand::Get(args) => get(args),
        ParamsCommand::Reset(args) => reset(args),
    }
}

/// The active set with the store's CRC, read so that a reply that changed on the way (or a set
/// that changed between the two requests) is caught rather than saved.
fn read_active(client: &mut imucal::device::DeviceClient) -> anyhow::Result<(CalibrationSet, u32)> {
    let crc = client.status()?.active_crc;
    let set = client.get_params()?;
    anyhow::ensure!(
        set.crc32() == crc,
        "the set read from {} has CRC {:#010x}, but the board reports {crc:#010x} as active; \
         nothing was written, run the command again",
        client.port_name(),
        set.crc32()
    );
    Ok((set, crc))
}

fn get(args: &GetArgs) -> anyhow::Result<()> {
    check_outputs(&[Output::File(&args.output)], &[], args.force)?;
    let (mut client, _board) = connect(&args.port)?;
    let (set, crc) = read_active(&mut client)?;
    let welcome = *client.welcome();
    let device_id = welcome.device_id.to_string();
    let mut file = ParamsFile::from(&set).bound_to(&welcome);
    file.provenance = Some(Provenance {
        tool: Provenance::tool(),
        source: format!("the active set of device {device_id}, read from the board"),
        device_id: Some(device_id.clone()),
        methods: Default::default(),
        input_units: Default::default(),
        created_unix_s: imucal::pipeline::calibrate::now_unix_s(),
        board_firmware: None,
    });
    let shown = args.output.display();
    std::fs::write(&args.output, file.to_json())
        .with_context(|| format!("could not write `{shown}`"))?;
    println!(
        "read the active set of device {device_id} ({}, CRC {crc:#010x}) into {shown}; \
         `imucal flash {shown}` writes it back to this board",
        describe_params(&set)
    );
    Ok(())
}

fn reset(args: &ResetArgs) -> anyhow::Result<()> {
    let confirmation = Confirmation::possible(
        args.yes,
        "resetting erases the board's calibration, and standard input is not a terminal to ask \
         on; pass --yes to reset (save the set first with `imucal params get -o FILE`)",
    )?;
    super::history::check_before_writing(&args.history)?;
    let (mut client, _board) = connect(&args.port)?;
    let (set, crc) = read_active(&mut client)?;
    let device_id = client.welcome().device_id;
    let identity = CalibrationSet::identity();
    if crc == identity.crc32() {
        println!(
            "device {device_id} already holds the identity set (CRC {crc:#010x}); nothing to do"
        );
        return Ok(());
    }
    say!(
        "Device {device_id} holds: {} (CRC {crc:#010x}). `imucal params get -o FILE` saves it \
         first.",
        describe_params(&set)
    );
    confirmation.ask(&format!(
        "Reset device {device_id}'s calibration to identity"
    ))?;
    let status = client.reset_params_verified()?;
    println!(
        "reset device {device_id} on {} to identity (CRC {:#010x}, store sequence {}), verified \
         by reading it back",
        client.port_name(),
        status.active_crc,
        status.active_seq
    );
    // The history says what the board holds now, so that its fleet and changes do not go on
    // describing the erased set.
    let mut file = imucal::device::ParamsFile::from(&identity);
    for sensor in imucal::device::params_json::SENSOR_KEYS {
        file.not_fitted.insert(
            sensor.to_string(),
            "reset to identity by `imucal params reset`".into(),
        );
    }
    let welcome = client.welcome();
    let mut record = imucal::history::CalibrationRecord::new(
        &device_id.to_string(),
        imucal::history::RecordSource::Reset,
        file,
        status.active_crc,
    );
    record.firmware_version = Some(super::history::firmware_text(&welcome.firmware_version));
    super::history::record(&args.history, record)
}
