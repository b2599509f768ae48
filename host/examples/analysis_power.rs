//! The residual analysis in an open world (see `imucal::open_world`): simulated recordings with
//! one hidden effect, analysed as `imucal analyze` does.
//!
//! 1. controls: no effect, the false-acceptance rate per sensor;
//! 2. power sweep: each family at 0.5×–20× its detectable size → detection rate, and the
//!    confusion matrix (which verdict each simulated family gets);
//! 3. out-of-family effects at 1× and 5× the simulator's typical size → verdicts.
//!
//! ```text
//! cargo run --release -p imucal --example analysis_power -- [--quick] [--seeds N] [--threads N]
//!     [--section controls|power|out-of-family|all] [--short] [--oof-seeds N] [--oof-size S]
//! cargo run --release -p imucal --example analysis_power -- --show gyro.bias_random_walk=5 --seed 3
//! ```
//! `--quick`: 4 seeds and the short recording. Output: Markdown tables on stdout. `--show`: the
//! text report of one simulated recording (effects as on the simulator's command line).

use std::collections::BTreeMap;
use std::time::Instant;

use imucal::analysis::report;
use imucal::open_world::{
    analyse_simulated, base_chi2, detectable_size, parallel_map, Case, Outcome, RecordingShape,
    OUT_OF_FAMILY_CASES, POWER_CASES,
};
use imucal::recording::Sensor;
use imucal_hil_sim::effects::EffectRequest;

/// Multiples of the detectable size in the power sweep.
const MULTIPLES: [f64; 6] = [0.5, 1.0, 2.0, 5.0, 10.0, 20.0];
/// Seeds used to measure each detectable size.
const CALIBRATION_SEEDS: usize = 3;

struct Options {
    seeds: usize,
    threads: usize,
    section: String,
    shape: RecordingShape,
    show: Vec<EffectRequest>,
    seed: u64,
    /// Seeds of the out-of-family cells.
    oof_seeds: usize,
    /// Sizes (× the simulator's typical part) of the out-of-family effects.
    oof_sizes: Vec<f64>,
}

fn parse_options() -> Result<Options, String> {
    let mut o = Options {
        seeds: 20,
        threads: std::thread::available_parallelism().map_or(1, |n| n.get()),
        section: "all".into(),
        shape: RecordingShape::FULL,
        show: Vec::new(),
        seed: 0,
        oof_seeds: 20,
        oof_sizes: vec![1.0, 5.0],
    };
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut value = |name: &str| args.next().ok_or(format!("{name} needs a value"));
        match a.as_str() {
            "--quick" => {
                o.seeds = 4;
                o.oof_seeds = 4;
                o.shape = RecordingShape::SHORT;
            }
            "--short" => o.shape = RecordingShape::SHORT,
            "--seeds" => {
                o.seeds = value("--seeds")?
                    .parse()
                    .map_err(|_| "--seeds takes a number")?
            }
            "--threads" => {
                o.threads = value("--threads")?
                    .parse()
                    .map_err(|_| "--threads takes a number")?
            }
            "--section" => o.section = value("--section")?,
            "--oof-seeds" => {
                o.oof_seeds = value("--oof-seeds")?
                    .parse()
                    .map_err(|_| "--oof-seeds takes a number")?
            }
            "--oof-size" => {
                o.oof_sizes = vec![value("--oof-size")?
                    .parse()
                    .map_err(|_| "--oof-size takes a number")?]
            }
            "--show" => o
                .show
                .push(value("--show")?.parse().map_err(|e| format!("{e}"))?),
            "--seed" => {
                o.seed = value("--seed")?
                    .parse()
                    .map_err(|_| "--seed takes a number")?
            }
            other => return Err(format!("unknown argument `{other}`")),
        }
    }
    Ok(o)
}

/// Per seed without effects: each sensor's verdict and base χ².
type CleanRuns = BTreeMap<u64, Vec<(Sensor, Outcome, Option<f64>)>>;

/// Verdict counts, in a stable order.
type Counts = BTreeMap<String, usize>;

fn count(outcomes: &[Outcome]) -> Counts {
    let mut c = Counts::new();
    for o in outcomes {
        *c.entry(o.label()).or_default() += 1;
    }
    c
}

fn format_counts(c: &Counts) -> String {
    c.iter()
        .map(|(k, v)| format!("{k} {v}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// Analyse `size` of `case` over `seeds`; the verdict for the case's sensor.
fn outcomes(case: &Case, size: f64, seeds: &[u64], o: &Options) -> Vec<Outcome> {
    parallel_map(seeds, o.threads, |&seed| {
        match analyse_simulated(&o.shape.config(seed, &[case.request(size)])) {
            Ok(a) => Outcome::of_sensor(&a, case.analysed()),
            Err(e) => Outcome::Failed(e),
        }
    })
}

fn controls(seeds: &[u64], o: &Options) -> CleanRuns {
    let results = parallel_map(seeds, o.threads, |&seed| {
        let a = analyse_simulated(&o.shape.config(seed, &[]));
        let per_sensor: Vec<(Sensor, Outcome, Option<f64>)> =
            [Sensor::Accel, Sensor::Gyro, Sensor::Mag]
                .into_iter()
                .map(|s| match &a {
                    Ok(a) => (s, Outcome::of_sensor(a, s), base_chi2(a, s)),
                    Err(e) => (s, Outcome::Failed(e.clone()), None),
                })
                .collect();
        (seed, per_sensor)
    });
    results.into_iter().collect()
}

fn main() {
    let o = match parse_options() {
        Ok(o) => o,
        Err(e) => {
            eprintln!("analysis_power: {e}");
            std::process::exit(2);
        }
    };
    if !o.show.is_empty() {
        match analyse_simulated(&o.shape.config(o.seed, &o.show)) {
            Ok(a) => println!("{}", report::to_text(&a)),
            Err(e) => eprintln!("analysis_power: {e}"),
        }
        return;
    }
    let started = Instant::now();
    let seeds: Vec<u64> = (0..o.seeds as u64).collect();
    println!(
        "# Residual analysis in an open world\n\nRecording: sweep schedule, {} poses ({} rounds of the twelve positions, holds of {} s, {} temperature cycle(s) 5–45 °C); {} seeds per cell; {} thread(s).\n",
        o.shape.poses(),
        o.shape.repeats,
        o.shape.hold_s,
        o.shape.cycles,
        o.seeds,
        o.threads
    );
    let all = o.section == "all";
    let needs_clean = all || o.section == "controls" || o.section == "power";
    let clean = if needs_clean {
        controls(&seeds, &o)
    } else {
        BTreeMap::new()
    };
    if all || o.section == "controls" {
        println!("## Controls (no effect)\n\n| sensor | analyses | any family accepted | verdicts |\n|---|---|---|---|");
        for s in [Sensor::Accel, Sensor::Gyro, Sensor::Mag] {
            let v: Vec<Outcome> = clean
                .values()
                .flat_map(|r| {
                    r.iter()
                        .filter(|(k, _, _)| *k == s)
                        .map(|(_, o, _)| o.clone())
                })
                .collect();
            let accepted = v.iter().filter(|o| !o.accepted().is_empty()).count();
            println!(
                "| {s} | {} | {accepted} ({:.1} %) | {} |",
                v.len(),
                100.0 * accepted as f64 / v.len().max(1) as f64,
                format_counts(&count(&v))
            );
        }
        println!();
    }
    if all || o.section == "power" {
        power_sweep(&seeds, &clean, &o);
    }
    if all || o.section == "out-of-family" {
        let oof_seeds: Vec<u64> = (0..o.oof_seeds as u64).collect();
        out_of_family(&oof_seeds, &o);
    }
    eprintln!("done in {:.0} s", started.elapsed().as_secs_f64());
}

fn power_sweep(seeds: &[u64], clean: &CleanRuns, o: &Options) {
    let mut detection = String::from(
        "## Power sweep: detection rate (the right family accepted)\n\n| family | sensor | detectable size (× typical) | λ_crit |",
    );
    for m in MULTIPLES {
        detection.push_str(&format!(" {m}× |"));
    }
    detection.push_str("\n|---|---|---|---|");
    detection.push_str(&"---|".repeat(MULTIPLES.len()));
    let mut confusion = String::from(
        "## Confusion: verdicts per simulated family (all sizes ≥ 2× detectable pooled)\n\n| simulated | sensor | verdicts |\n|---|---|---|",
    );
    for case in &POWER_CASES {
        let cal_seeds: Vec<u64> = seeds.iter().copied().take(CALIBRATION_SEEDS).collect();
        let clean_chi2: Vec<f64> = cal_seeds
            .iter()
            .map(|s| {
                clean
                    .get(s)
                    .and_then(|r| r.iter().find(|(k, _, _)| *k == case.analysed()))
                    .and_then(|(_, _, c)| *c)
                    .unwrap_or(f64::NAN)
            })
            .collect();
        let det = match detectable_size(case, &o.shape, &cal_seeds, &clean_chi2, o.threads) {
            Ok(d) => d,
            Err(e) => {
                eprintln!("{}: {e}", case.label());
                continue;
            }
        };
        eprintln!(
            "{}: detectable size {:.3e} (λ {:.1} at size {:.3e}, critical {:.1})",
            case.label(),
            det.size,
            det.measured,
            det.calibration_size,
            det.critical
        );
        let family = case.effect.name();
        detection.push_str(&format!(
            "\n| {family} | {} | {:.3} | {:.1} |",
            case.sensor.name(),
            det.size,
            det.critical
        ));
        let mut pooled = Vec::new();
        for m in MULTIPLES {
            let v = outcomes(case, m * det.size, seeds, o);
            let hits = v.iter().filter(|x| x.accepted().contains(&family)).count();
            detection.push_str(&format!(
                " {:.0} % |",
                100.0 * hits as f64 / v.len().max(1) as f64
            ));
            eprintln!("  {m}×: {}", format_counts(&count(&v)));
            if m >= 2.0 {
                pooled.extend(v);
            }
        }
        confusion.push_str(&format!(
            "\n| {family} | {} | {} |",
            case.sensor.name(),
            format_counts(&count(&pooled))
        ));
    }
    println!("{detection}\n\n{confusion}\n");
}

fn out_of_family(seeds: &[u64], o: &Options) {
    println!("## Out-of-family effects: verdicts\n\n| effect | sensor | size (× typical) | verdicts | a family accepted with residual left |\n|---|---|---|---|---|");
    for case in &OUT_OF_FAMILY_CASES {
        for &size in &o.oof_sizes {
            let v = outcomes(case, size, seeds, o);
            let partial = v
                .iter()
                .filter(|x| matches!(x, Outcome::Partial(_)))
                .count();
            println!(
                "| {} | {} | {size} | {} | {partial} |",
                case.effect.name(),
                case.sensor.name(),
                format_counts(&count(&v))
            );
        }
    }
    println!();
}
